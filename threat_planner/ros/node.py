"""
ROS 2 node ``threat_planner``: replans a threat-aware path whenever its inputs change.

Topics (all relative, so a namespace or remapping moves them together):

========================  ==================================  ==============================
topic                     type                                QoS
========================  ==================================  ==============================
``threats`` (in)          sensor_msgs/PointCloud2             reliable, transient local, 10
``threat_poses`` (in)     geometry_msgs/PoseArray             reliable, transient local, 10
``start`` (in)            geometry_msgs/PoseStamped           reliable, volatile, 10
``goal_pose`` (in)        geometry_msgs/PoseStamped           reliable, volatile, 10
``start_fix``, ``goal_fix`` sensor_msgs/NavSatFix (``datum``)  best effort, volatile, 10
``no_fly_zones`` (in)     visualization_msgs/MarkerArray      reliable, transient local, 10
``terrain`` (in)          sensor_msgs/Image (32FC1)           reliable, transient local, 10
``odom`` (in)             nav_msgs/Odometry                   best effort, volatile, 10
``initial_path`` (out)    nav_msgs/Path (Dijkstra path)       reliable, transient local, 1
``path`` (out)            nav_msgs/Path (final path)          reliable, transient local, 1
``network`` (out)         visualization_msgs/MarkerArray      reliable, transient local, 1
``plan_info`` (out)       diagnostic_msgs/DiagnosticArray     reliable, transient local, 1
========================  ==================================  ==============================

QoS and the reasons for it: :mod:`threat_planner.ros.interface`; the airspace messages:
:mod:`threat_planner.ros.conversions.airspace`, with parameter ``airspace_file`` and which
input wins: :mod:`threat_planner.ros.airspace_input`.

Every accepted input (a threat picture, start, goal or parameter change) gets the next
input sequence number and triggers a replan; the vehicle's ``odom`` replans only by the
rule of :mod:`threat_planner.ros.flight` (plans from the vehicle, in flight and through
moving threats: :mod:`threat_planner.ros.flight_plan`). Planning runs in a worker thread so the
executor keeps serving callbacks; inputs that arrive while a plan runs are coalesced into a
single pending request holding the latest state (latest wins), and every request replaced
that way is counted as ``inputs_skipped``. ``initial_path`` and ``path`` are published as
soon as a plan is done, ``network`` and ``plan_info`` once its markers are drawn (for 1000
threats that takes ~0.1 s). Each ``plan_info`` names the input it answers
(``input_seq``, ``input_source``, ``input_stamp_ns``), and every output header carries that
input's stamp (the node clock's time of a parameter change).

A bad input (NaN/inf, F <= 0, too many threats, start or goal outside the bounds or on a
threat, a malformed PointCloud2, a frame_id other than parameter ``frame_id``) is refused
whole: one ERROR log line, an ERROR ``plan_info`` carrying the reason, and the previous
plan stays latched on ``initial_path``, ``path`` and ``network``.

Parameter ``record`` (a path; '' = off) records every input with its receive time and
every output with its publish time to MCAP (a file if it ends in ``.mcap``, else a folder
holding one rosbag2 bag per run). Parameter changes are recorded as
``rcl_interfaces/msg/ParameterEvent`` on ``/parameter_events``: when a recording starts,
one event lists every parameter of this node as new, then each accepted change follows.
"""

from __future__ import annotations

import collections
import threading
from typing import Callable, Optional, TYPE_CHECKING

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Odometry, Path
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image, NavSatFix, PointCloud2
from visualization_msgs.msg import MarkerArray

from threat_planner.core.compiled import ensure_compiled, kernels_cached
from threat_planner.errors import InputError, RecordingError
from threat_planner.ros.conversions import path_from_msg, plan_info_msg
from threat_planner.ros.flight import FlightTracker
from threat_planner.ros.inputs import accept, input_stamp, InputState
from threat_planner.ros.interface import (FIX_INPUT, LATCHED, NODE_NAME, POSE_INPUT,
                                          THREAT_INPUT)
from threat_planner.ros.outputs import input_values, outcome_messages, PlanOutcome, PlanRequest
from threat_planner.ros.parameters import declare_all, PARAMETER_DEFAULTS, PLANNING_PARAMETERS
from threat_planner.ros.node_recording import NodeRecording
from threat_planner.ros.plan_service import PlanService
from threat_planner.ros.process import run_node
from threat_planner.ros.worker import ProcessPlanWorker
if TYPE_CHECKING:  # mcap loads when a recording opens, not at every start
    from threat_planner.bag import McapRecorder

__all__ = ['ThreatPlannerNode', 'main']


class ThreatPlannerNode(NodeRecording, Node):
    """The planner node; see the module docstring.

    Parameters
    ----------
    **kwargs
        Passed to :class:`rclpy.node.Node` (for example ``context`` or ``cli_args``).

    Raises
    ------
    InputError
        If the parameters given at start-up are invalid or inconsistent.
    rclpy.exceptions.ParameterException
        If a start-up parameter has the wrong type or is out of its descriptor's range.
    RecordingError
        If parameter ``record`` names a recording that cannot be created.

    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        # Subscriptions first: DDS discovery, a start's longest wait, runs beside the set-up
        # below (no callback before the spin). node_start: first path 1.04 -> 0.95 s.
        self._create_inputs()
        self._configure()
        self._create_outputs(self.create_publisher)
        self._plan_service: Optional[PlanService] = PlanService(self, lambda: self._state)
        self._log_ready()

    # -- set-up steps, shared with the managed node (issue 13: ros/lifecycle.py) ------

    def _declare_parameters(self) -> None:
        declare_all(self)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

    def _configure(self) -> None:
        """Validate the parameters into the state, start the worker, open the recording."""
        self._state = InputState.from_parameters(self._parameter_values())
        self._seq = self._received = self._rejected = self._skipped = self._plans = 0
        self._flight = FlightTracker()   # flight (issue 44): the vehicle and its trajectory
        self._staged: Optional[tuple[InputState, Optional[McapRecorder]]] = None
        self._recorder: Optional[McapRecorder] = None
        self._outcomes: collections.deque[tuple[str, PlanOutcome]] = collections.deque()
        self._outcome_lock = threading.Lock()
        self._closed = False
        self._guard = self.create_guard_condition(self._publish_outcomes)
        # A cold cache compiles here, once, before the children start (they then load);
        # a warm one loads in the children and here at the same time.
        cached = kernels_cached()
        if not cached:
            self._load_kernels()
        # reliability (issue 14): plans run in a child process, the executor stays free.
        self._worker = ProcessPlanWorker(self._hand_over, name='threat_planner_worker')
        if cached:
            self._load_kernels()
        if self._state.settings.record:
            try:
                self._recorder = self._open_recorder(self._state.settings.record)
            except RecordingError:
                self._worker.stop()  # reliability (issue 14): no process left behind
                raise

    def _create_outputs(self, create: Callable) -> None:
        self._pubs = {
            'initial_path': create(Path, 'initial_path', LATCHED),
            'path': create(Path, 'path', LATCHED),
            'network': create(MarkerArray, 'network', LATCHED),
            'plan_info': create(DiagnosticArray, 'plan_info', LATCHED),
        }

    def _create_inputs(self) -> None:
        self._subs = {
            'threats': self.create_subscription(
                PointCloud2, 'threats', lambda m: self._receive('threats', m), THREAT_INPUT),
            'threat_poses': self.create_subscription(
                PoseArray, 'threat_poses', lambda m: self._receive('threat_poses', m),
                THREAT_INPUT),
            'start': self.create_subscription(
                PoseStamped, 'start', lambda m: self._receive('start', m), POSE_INPUT),
            'goal_pose': self.create_subscription(
                PoseStamped, 'goal_pose', lambda m: self._receive('goal_pose', m),
                POSE_INPUT),
            # airspace (issue 12): whole zone sets and height maps, latched like threats
            'no_fly_zones': self.create_subscription(
                MarkerArray, 'no_fly_zones', lambda m: self._receive('no_fly_zones', m),
                THREAT_INPUT),
            'terrain': self.create_subscription(
                Image, 'terrain', lambda m: self._receive('terrain', m), THREAT_INPUT),
            # geo (issue 26): GNSS fixes, converted with parameter datum
            **{k: self.create_subscription(NavSatFix, k, lambda m, k=k: self._receive(k, m),
                                           FIX_INPUT) for k in ('start_fix', 'goal_fix')},
            # flight (issue 44): the vehicle's odometry, a sensor stream
            'odom': self.create_subscription(
                Odometry, 'odom', lambda m: self._receive('odom', m), FIX_INPUT),
        }

    def _load_kernels(self) -> None:
        """Load (or, once per install, compile) the kernels before any input can arrive.

        The GetPlan service plans in this process and the worker children load from the
        cache this fills, so neither the first request nor the first picture waits on it.
        """
        report = ensure_compiled()
        # One info line: which kernels plans use (AOT or JIT, and why), what loading took.
        self.get_logger().info(f'kernels: {report.line()}')

    def _log_ready(self) -> None:
        settings = self._state.settings
        cfg = settings.config
        self.get_logger().info(
            f'ready: method={cfg.method} w={cfg.w} frame_id={settings.frame_id} '
            f'bounds={settings.box.lo.tolist()}..{settings.box.hi.tolist()}; '
            f'waiting for a threat picture on {self.resolve_topic_name("threats")} or '
            f'{self.resolve_topic_name("threat_poses")}')

    # -- parameters ------------------------------------------------------------------

    def _parameter_values(self) -> dict[str, object]:
        return {name: self.get_parameter(name).value for name in PARAMETER_DEFAULTS}

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Refuse a change whose value, or whose combination with the state, is bad."""
        if self._state is None:
            # A managed node before configure: the values are checked on configure.
            return SetParametersResult(successful=True)
        names = {p.name for p in params}
        try:
            state = accept(self._state, 'parameters',
                           {p.name: p.value for p in params if p.name in PARAMETER_DEFAULTS})
            record = state.settings.record
            recorder = None
            if 'record' in names and record and (
                    record != self._state.settings.record or self._recorder is None):
                recorder = self._open_recorder(record)
        except (InputError, RecordingError) as exc:
            reason = str(exc)
            self.get_logger().warning(f'parameter change refused: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        self._staged = (state, recorder)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Take a validated change into use: recorder, state and a replan."""
        if self._staged is None:
            return
        state, recorder = self._staged
        self._staged = None
        names = {p.name for p in params}
        previous, self._state = self._state, state
        if previous.settings.frame_id != state.settings.frame_id:
            self._flight.reset()   # the trajectory flown is in the old frame
        if previous.threats is not None and state.threats is None:
            self._frame_changed(previous.settings.frame_id, state.settings.frame_id)
        if 'record' in names and (recorder is not None or not state.settings.record):
            self._close_recorder()
            self._recorder = recorder
        self._record_parameter_event(params)
        self._seq += 1
        self._received += 1
        changed = ', '.join(f'{p.name}={p.value!r}' for p in params)
        self.get_logger().info(f'input #{self._seq} (parameters): {changed}')
        if names & PLANNING_PARAMETERS:
            self._request_plan('parameters', self.get_clock().now().to_msg())

    def _frame_changed(self, old: str, new: str) -> None:
        # reliability (issue 14): say that the picture of the old frame is gone.
        message = (f'frame_id changed from {old!r} to {new!r}: the threat picture received '
                   f'in {old!r} was dropped; no plan until a picture in {new!r} arrives')
        self.get_logger().warning(message)
        stamp = self.get_clock().now().to_msg()
        values = self._input_values(self._seq + 1, 'parameters', stamp)
        values['threats_dropped'] = 'true'
        self._publish('plan_info', plan_info_msg('WARN', message, values, stamp))

    # -- inputs ----------------------------------------------------------------------

    def _receive(self, kind: str, msg) -> None:
        """Record, number and take one input message; a refused one leaves the state."""
        topic = self._subs[kind].topic_name
        self._record(topic, msg)
        self._seq += 1
        self._received += 1
        stamp = input_stamp(msg)  # airspace (issue 12): a MarkerArray has no header
        now = self._now_ns()
        try:
            self._state = self._flight.took(accept(self._state, kind, msg), kind, now)
        except InputError as exc:
            if kind == 'odom' and not self._flight.refused(str(exc)):
                self._rejected += 1   # counted in plan_info; said once per kind of reason
                return
            self._reject(topic, stamp, str(exc))
            return
        reason = self._flight.trigger(self._state, now) if kind == 'odom' else ''
        if reason is not None:
            self._request_plan(topic, stamp, reason)

    def _reject(self, source: str, stamp: Time, reason: str) -> None:
        self._rejected += 1
        message = f'input #{self._seq} on {source} rejected: {reason}'
        self.get_logger().error(message)
        values = self._input_values(self._seq, source, stamp)
        values['error'] = reason
        self._publish('plan_info', plan_info_msg('ERROR', message, values, stamp))

    def _request_plan(self, source: str, stamp: Time, reason: str = '') -> None:
        state = self._state
        if state.threats is None:
            self.get_logger().info(
                f'input #{self._seq} ({source}) stored; no plan until a threat picture '
                'arrives')
            return
        now = self._now_ns()
        flight = self._flight.request_fields(state, now)
        if flight is None:
            self.get_logger().info(f'input #{self._seq} ({source}): the vehicle is within '
                                   'commit_s of the goal; the trajectory flown stands')
            return
        request = PlanRequest(seq=self._seq, source=source, stamp=stamp, received_ns=now,
                              threats=state.threats, start=state.start, goal=state.goal,
                              settings=state.settings,
                              airspace=state.airspace,  # airspace (issue 12)
                              velocities=state.velocities,  # flight (issue 44)
                              threats_t_ns=state.threats_stamp_ns, reason=reason, **flight)
        self._flight.requested(request)
        if self._worker.submit(request):
            self._skipped += 1

    # -- planning (worker thread) ----------------------------------------------------

    def _hand_over(self, phase: str, outcome: PlanOutcome) -> None:
        """Queue a phase of a plan for the executor thread and wake it."""
        with self._outcome_lock:
            self._outcomes.append((phase, outcome))
        try:
            self._guard.trigger()
        except Exception:  # noqa: B902 - the node may be torn down while a plan ran
            pass

    # -- outputs (executor thread) ---------------------------------------------------

    def _publish(self, name: str, msg) -> None:
        publisher = self._pubs[name]
        publisher.publish(msg)
        self._record(publisher.topic_name, msg)

    def _input_values(self, seq: int, source: str, stamp: Time) -> dict[str, object]:
        return input_values(seq, source, stamp, self._state.settings.frame_id,
                            self._received, self._rejected, self._skipped, self._plans,
                            self._flight.odom_rejected)

    def _publish_outcomes(self) -> None:
        while True:
            with self._outcome_lock:
                if not self._outcomes or self._closed:
                    return
                phase, outcome = self._outcomes.popleft()
            req = outcome.request
            self._track(phase, outcome)
            if phase == 'cancelled':
                self._skipped += 1
                self.get_logger().info(f'plan for input #{req.seq} cancelled after '
                                       f'{outcome.plan_ms / 1e3:.1f} s: a newer input waits')
                continue
            if phase == 'done':
                self._plans += 1
                if outcome.network is None:
                    self.get_logger().warning(f'input #{req.seq}: network markers not '
                                              f'drawn: {outcome.network_error}')
            messages = outcome_messages(phase, outcome,
                                        self._input_values(req.seq, req.source, req.stamp))
            for name, msg in messages:
                self._publish(name, msg)
            if phase == 'done':
                self.get_logger().info(messages[-1][1].status[0].message)
            elif phase == 'error':
                self.get_logger().error(messages[-1][1].status[0].message)
            elif phase == 'timeout':   # issue 14: timed out, best path so far published
                self.get_logger().warning(messages[-1][1].status[0].message)

    def _track(self, phase: str, outcome: PlanOutcome) -> None:
        """Note the trajectory published (the one the vehicle flies) and the plan's end."""
        path = {'paths': outcome.path, 'timeout': outcome.best_so_far}.get(phase)
        if path is not None:
            self._flight.planned(outcome.request, path_from_msg(path))
        if phase in ('paths', 'error', 'timeout'):
            self._flight.answered(outcome.request.seq)

    # -- life cycle ------------------------------------------------------------------

    @property
    def recorder(self) -> Optional[McapRecorder]:
        """The open recorder, if parameter ``record`` is set."""
        return self._recorder

    def close(self) -> None:
        """Stop the worker and close the recording; idempotent."""
        if not self._worker.stop():
            self.get_logger().warning('shutting down while a plan is still running; '
                                      'its result is dropped')
        with self._outcome_lock:
            self._closed = True
        if self._plan_service is not None:
            self._plan_service.close()
            self._plan_service = None
        self._close_recorder()


def main(args: Optional[list[str]] = None) -> int:
    """Run the node until SIGINT or SIGTERM, then close the recording and exit.

    Parameters
    ----------
    args : list of str, optional
        Command line (``--ros-args ...``); ``sys.argv`` if None.

    Returns
    -------
    int
        0 after a clean shutdown, 1 if the start-up parameters were refused.

    """
    return run_node(ThreatPlannerNode, NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())
