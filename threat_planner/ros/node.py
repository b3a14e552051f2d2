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
``initial_path`` (out)    nav_msgs/Path (Dijkstra path)       reliable, transient local, 1
``path`` (out)            nav_msgs/Path (final path)          reliable, transient local, 1
``network`` (out)         visualization_msgs/MarkerArray      reliable, transient local, 1
``plan_info`` (out)       diagnostic_msgs/DiagnosticArray     reliable, transient local, 1
========================  ==================================  ==============================

A threat message is the whole threat picture (it replaces the previous one), so the threat
inputs subscribe transient local like a map: a node started after a latched publisher still
gets the current picture. A publisher of threats must therefore offer transient local
durability (a volatile one is reported by rclpy as incompatible QoS). Start and goal
subscribe volatile so that RViz's pose tools (volatile publishers) work.

Every accepted input (a threat picture, start, goal or parameter change) gets the next
input sequence number and triggers a replan. Planning runs in a worker thread so the
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
from dataclasses import dataclass
import math
import threading
import time
from typing import Callable, Mapping, Optional, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Path
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterEvent, SetParametersResult)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

from threat_planner.ros.conversions import (network_markers, path_to_msg, plan_info_msg,
                                            point_from_pose_stamped, stamp_to_ns,
                                            threats_from_pointcloud2, threats_from_pose_array)
from threat_planner.errors import InputError, PlanningError, RecordingError
from threat_planner.core.planner import check_endpoints, plan, PlannerConfig, PlanResult
from threat_planner.bag import McapRecorder, TopicQos
from threat_planner.ros.process import run_node
from threat_planner.core.threats import as_point, Box, ThreatField

__all__ = ['NodeSettings', 'PARAMETER_DEFAULTS', 'PlanWorker', 'ThreatPlannerNode',
           'input_values', 'main', 'plan_done_info', 'plan_markers',
           'settings_from_parameters']

NODE_NAME = 'threat_planner'

#: Outputs: late subscribers (RViz, a recorder) get the last plan.
LATCHED = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=1)
#: Threat pictures: state, like a map (see the module docstring).
THREAT_INPUT = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          history=HistoryPolicy.KEEP_LAST, depth=10)
#: Start and goal: volatile, as RViz's pose tools publish.
POSE_INPUT = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE,
                        history=HistoryPolicy.KEEP_LAST, depth=10)
#: rclpy's parameter events QoS, for the recording's channel metadata.
PARAMETER_EVENTS_QOS = TopicQos(reliability='reliable', durability='volatile',
                                history='keep_last', depth=1000)
PARAMETER_EVENTS_TOPIC = '/parameter_events'

_DEFAULT_CONFIG = PlannerConfig()

#: Every parameter's default, as in ``config/planner.yaml``.
PARAMETER_DEFAULTS: dict[str, object] = {
    'w': _DEFAULT_CONFIG.w,
    'method': _DEFAULT_CONFIG.method,
    'k': _DEFAULT_CONFIG.k,
    'auto_k': _DEFAULT_CONFIG.auto_k,
    'damping': _DEFAULT_CONFIG.damping,
    'mass': _DEFAULT_CONFIG.mass,
    'q': _DEFAULT_CONFIG.q,
    'n_points': _DEFAULT_CONFIG.n_points,
    'max_pitch_deg': _DEFAULT_CONFIG.max_pitch_deg,
    'max_turn_deg': _DEFAULT_CONFIG.max_turn_deg,
    'entry_candidates': _DEFAULT_CONFIG.entry_candidates,
    'confine_to_box': _DEFAULT_CONFIG.confine_to_box,
    'bounds': [0.0, 0.0, 0.0, 100.0, 100.0, 100.0],
    'frame_id': 'map',
    'start': [0.0, 0.0, 50.0],
    'goal': [100.0, 100.0, 50.0],
    'default_intensity': 100000.0,
    'max_threats': 10000,
    'record': '',
}

# name: (description, (from, to) range or None, extra constraint text)
_PARAMETER_DOCS: dict[str, tuple[str, Optional[tuple[float, float]], str]] = {
    'w': ('Threat weight in J = w J_R + (1 - w) J_L', (0.0, 1.0), '0 < w < 1'),
    'method': ("Planning method: 'paper', 'improved' or 'best'", None,
               "one of 'paper', 'improved', 'best'"),
    'k': ('Spring coefficient of the smoothing chain', (0.0, 1.0e6), 'k > 0'),
    'auto_k': ('Sweep k over 500..3000 for the least J (paper Case 3)', None, ''),
    'damping': ('Damping coefficient b between neighbouring chain masses', (0.0, 1.0e6),
                'b >= 0'),
    'mass': ('Mass M of each chain point', (0.0, 1.0e6), 'M > 0'),
    'q': ('Repulsion constant Q of the threat potential', (0.0, 1.0e9), 'Q >= 0'),
    'n_points': ('Number of chain segments n of the final path (n + 1 points)',
                 (2, 10000), ''),
    'max_pitch_deg': ('Pitch limit [deg]', (0.0, 90.0), '0 < limit <= 90'),
    'max_turn_deg': ('Turn limit between consecutive segments [deg]', (0.0, 180.0),
                     '0 < limit <= 180'),
    'entry_candidates': ('Nearest network nodes tried as entry and as exit', (1, 64), ''),
    'confine_to_box': ('Keep the optimised path inside the bounds', None, ''),
    'bounds': ('Flight box [xmin, ymin, zmin, xmax, ymax, zmax] [m] in frame_id', None,
               '6 finite numbers, max > min on every axis'),
    'frame_id': ('Frame of every input and output; inputs in another frame are refused',
                 None, 'non-empty'),
    'start': ('Start [x, y, z] [m], used until a start message arrives; setting it '
              'replaces the current start', None, '3 finite numbers inside bounds'),
    'goal': ('Goal [x, y, z] [m], used until a goal_pose message arrives; setting it '
             'replaces the current goal', None, '3 finite numbers inside bounds'),
    'default_intensity': ('Intensity F given to every threat of a PoseArray',
                          (0.0, 1.0e12), 'F > 0'),
    'max_threats': ('Largest threat picture accepted', (0, 1_000_000), ''),
    'record': ("MCAP recording of inputs and outputs: a path ending in .mcap (one file) "
               "or a folder (one bag per run); '' = off", None, ''),
}

# Parameters whose change can alter the plan; the rest (recording, input limits) cannot.
_PLANNING_PARAMETERS = frozenset(PARAMETER_DEFAULTS) - {'record', 'max_threats',
                                                        'default_intensity'}
_CONFIG_FIELDS = ('w', 'method', 'k', 'auto_k', 'damping', 'mass', 'q', 'n_points',
                  'max_pitch_deg', 'max_turn_deg', 'entry_candidates', 'confine_to_box')
_ARRAY_PARAMETERS = frozenset({'bounds', 'start', 'goal'})
_NO_THREATS = ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0))
# A plan that cannot finish within this after shutdown is abandoned (the worker is a
# daemon thread): a 1000-threat 'best' plan takes tens of seconds and must not hold up
# SIGINT or SIGTERM. Its result would be dropped anyway, so waiting only lets an idle
# worker end; the node must exit within 1 s of the signal.
_WORKER_JOIN_S = 0.1


# ------------------------------------------------------------------------ settings


@dataclass(frozen=True)
class NodeSettings:
    """The node's parameters, validated and converted.

    Attributes
    ----------
    config : PlannerConfig
        Planner settings.
    box : Box
        Flight box.
    frame_id : str
        Frame of all inputs and outputs.
    start : NDArray
        Start parameter (3,) [m].
    goal : NDArray
        Goal parameter (3,) [m].
    default_intensity : float
        Intensity of PoseArray threats.
    max_threats : int
        Largest accepted threat picture.
    record : str
        Recording target, '' for none.

    """

    config: PlannerConfig
    box: Box
    frame_id: str
    start: NDArray
    goal: NDArray
    default_intensity: float
    max_threats: int
    record: str


def _numbers(name: str, value: object, count: int, what: str) -> NDArray:
    if isinstance(value, (str, bytes, bool)) or not hasattr(value, '__len__'):
        raise InputError(f'{name}: expected {what}, got {value!r}')
    try:
        arr = np.asarray(list(value), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected {what}, got {value!r}') from None
    if arr.shape != (count,):
        raise InputError(f'{name}: expected {what}, got {arr.size} values')
    if not np.isfinite(arr).all():
        raise InputError(f'{name}: not finite: {arr.tolist()}')
    return arr


def settings_from_parameters(values: Mapping[str, object]) -> NodeSettings:
    """Validate parameter values and convert them to NodeSettings.

    Parameters
    ----------
    values : Mapping[str, object]
        Every name of :data:`PARAMETER_DEFAULTS` with its value (as rclpy gives it:
        float arrays may be lists, tuples or ``array.array``).

    Returns
    -------
    NodeSettings
        The converted settings.

    Raises
    ------
    InputError
        Naming the first bad parameter and its value; the text of
        ``PlannerConfig.validated()`` for planner settings.

    """
    try:
        config = PlannerConfig(**{name: values[name] for name in _CONFIG_FIELDS})
    except TypeError as exc:
        raise InputError(f'planner settings: {exc}') from None
    config.validated()
    bounds = _numbers('bounds', values['bounds'], 6,
                      '6 numbers [xmin, ymin, zmin, xmax, ymax, zmax]')
    try:
        box = Box.from_corners(bounds[:3], bounds[3:])
    except InputError as exc:
        raise InputError(str(exc).replace('bounds.min', 'bounds').replace(
            'bounds.max', 'bounds')) from None
    start = as_point('start', _numbers('start', values['start'], 3, '[x, y, z]'))
    goal = as_point('goal', _numbers('goal', values['goal'], 3, '[x, y, z]'))
    frame_id = values['frame_id']
    if not isinstance(frame_id, str) or not frame_id.strip():
        raise InputError(f'frame_id: must be a non-empty string, got {frame_id!r}')
    intensity = float(values['default_intensity'])
    if not (math.isfinite(intensity) and intensity > 0.0):
        raise InputError(f'default_intensity: must be finite and > 0, got {intensity!r}')
    max_threats = values['max_threats']
    if isinstance(max_threats, bool) or not isinstance(max_threats, int) or max_threats < 0:
        raise InputError(f'max_threats: must be an integer >= 0, got {max_threats!r}')
    record = values['record']
    if not isinstance(record, str):
        raise InputError(f'record: must be a string, got {record!r}')
    return NodeSettings(config, box, frame_id, start, goal, intensity, max_threats,
                        record.strip())


def _descriptor(name: str) -> ParameterDescriptor:
    description, bounds, constraints = _PARAMETER_DOCS[name]
    default = PARAMETER_DEFAULTS[name]
    desc = ParameterDescriptor(name=name, description=description,
                               additional_constraints=constraints)
    if bounds is not None and isinstance(default, float):
        desc.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                        to_value=float(bounds[1]), step=0.0)]
    elif bounds is not None and isinstance(default, int) and not isinstance(default, bool):
        desc.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]),
                                           step=1)]
    if name in _ARRAY_PARAMETERS:
        # `-p bounds:=[0,0,0,100,100,100]` arrives as an integer array; accept it and
        # check the numbers ourselves rather than refuse it for its element type.
        desc.dynamic_typing = True
    return desc


# -------------------------------------------------------------------------- worker


class PlanWorker:
    """Runs one job at a time in a daemon thread, with a single latest-wins pending slot.

    Parameters
    ----------
    run : Callable[[object], None]
        Called in the worker thread with each job; must not raise.
    name : str
        Thread name.

    """

    def __init__(self, run: Callable[[object], None], name: str = 'planner') -> None:
        self._run = run
        self._cond = threading.Condition()
        self._pending: Optional[object] = None
        self._busy = False
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: object) -> bool:
        """Make `job` the next one to run.

        Parameters
        ----------
        job : object
            The job.

        Returns
        -------
        bool
            True if it replaced a pending job that had not started (that job is skipped).

        """
        with self._cond:
            if self._stopping:
                return False
            replaced = self._pending is not None
            self._pending = job
            self._cond.notify()
        return replaced

    @property
    def busy(self) -> bool:
        """Whether a job is running."""
        with self._cond:
            return self._busy

    @property
    def has_pending(self) -> bool:
        """Whether a job waits for the running one."""
        with self._cond:
            return self._pending is not None

    def stop(self, timeout: float = _WORKER_JOIN_S) -> bool:
        """Drop the pending job and wait up to `timeout` s for the running one.

        Returns
        -------
        bool
            True if the thread ended within the timeout.

        """
        with self._cond:
            self._stopping = True
            self._pending = None
            self._cond.notify()
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
                job, self._pending = self._pending, None
                self._busy = True
            try:
                self._run(job)
            finally:
                with self._cond:
                    self._busy = False


# ---------------------------------------------------------------------------- node


@dataclass(frozen=True)
class _Request:
    """A snapshot of everything a plan needs, tagged with the input it answers."""

    seq: int
    source: str
    stamp: Time
    received_ns: int
    threats: ThreatField
    start: NDArray
    goal: NDArray
    settings: NodeSettings


@dataclass
class _Outcome:
    """What the worker hands back to the executor thread for publishing."""

    request: _Request
    result: Optional[PlanResult] = None
    initial_path: Optional[Path] = None
    path: Optional[Path] = None
    network: Optional[MarkerArray] = None
    network_error: Optional[str] = None
    error: Optional[str] = None
    queue_ms: float = 0.0
    plan_ms: float = 0.0
    messages_ms: float = 0.0


class ThreatPlannerNode(Node):
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
        for name, default in PARAMETER_DEFAULTS.items():
            self.declare_parameter(name, default, _descriptor(name))
        self._settings = settings_from_parameters(self._parameter_values())
        check_endpoints(self._settings.start, self._settings.goal, self._settings.box,
                        _NO_THREATS)
        self._start = self._settings.start
        self._goal = self._settings.goal
        self._threats: Optional[ThreatField] = None
        self._seq = 0
        self._received = 0
        self._rejected = 0
        self._skipped = 0
        self._plans = 0
        self._staged: Optional[tuple[NodeSettings, Optional[McapRecorder]]] = None
        self._recorder: Optional[McapRecorder] = None
        self._outcomes: collections.deque[tuple[str, _Outcome]] = collections.deque()
        self._outcome_lock = threading.Lock()
        self._closed = False

        self._pub_initial = self.create_publisher(Path, 'initial_path', LATCHED)
        self._pub_path = self.create_publisher(Path, 'path', LATCHED)
        self._pub_network = self.create_publisher(MarkerArray, 'network', LATCHED)
        self._pub_info = self.create_publisher(DiagnosticArray, 'plan_info', LATCHED)
        self._sub_threats = self.create_subscription(
            PointCloud2, 'threats', self._on_threats, THREAT_INPUT)
        self._sub_poses = self.create_subscription(
            PoseArray, 'threat_poses', self._on_threat_poses, THREAT_INPUT)
        self._sub_start = self.create_subscription(
            PoseStamped, 'start', self._on_start, POSE_INPUT)
        self._sub_goal = self.create_subscription(
            PoseStamped, 'goal_pose', self._on_goal, POSE_INPUT)
        self._guard = self.create_guard_condition(self._publish_outcomes)
        self._worker = PlanWorker(self._plan_job, name='threat_planner_worker')

        if self._settings.record:
            self._recorder = self._open_recorder(self._settings.record)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        cfg = self._settings.config
        self.get_logger().info(
            f'ready: method={cfg.method} w={cfg.w} frame_id={self._settings.frame_id} '
            f'bounds={self._settings.box.lo.tolist()}..{self._settings.box.hi.tolist()}; '
            f'waiting for a threat picture on {self._sub_threats.topic_name} or '
            f'{self._sub_poses.topic_name}')

    # -- parameters ------------------------------------------------------------------

    def _parameter_values(self, changes: Sequence[Parameter] = ()) -> dict[str, object]:
        values = {name: self.get_parameter(name).value for name in PARAMETER_DEFAULTS}
        values.update({p.name: p.value for p in changes if p.name in values})
        return values

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Refuse a change whose value, or whose combination with the state, is bad."""
        names = {p.name for p in params}
        try:
            settings = settings_from_parameters(self._parameter_values(params))
            start = settings.start if 'start' in names else self._start
            goal = settings.goal if 'goal' in names else self._goal
            check_endpoints(start, goal, settings.box, self._known_threats)
            recorder = None
            if 'record' in names and settings.record and (
                    settings.record != self._settings.record or self._recorder is None):
                recorder = self._open_recorder(settings.record)
        except (InputError, RecordingError) as exc:
            reason = str(exc)
            self.get_logger().warning(f'parameter change refused: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        self._staged = (settings, recorder)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Take a validated change into use: recorder, state and a replan."""
        if self._staged is None:
            return
        settings, recorder = self._staged
        self._staged = None
        names = {p.name for p in params}
        self._settings = settings
        if 'record' in names and (recorder is not None or not settings.record):
            self._close_recorder()
            self._recorder = recorder
        self._record_parameter_event(params)
        if 'start' in names:
            self._start = settings.start
        if 'goal' in names:
            self._goal = settings.goal
        self._seq += 1
        self._received += 1
        changed = ', '.join(f'{p.name}={p.value!r}' for p in params)
        self.get_logger().info(f'input #{self._seq} (parameters): {changed}')
        if names & _PLANNING_PARAMETERS:
            self._request_plan('parameters', self.get_clock().now().to_msg())

    # -- recording -------------------------------------------------------------------

    def _open_recorder(self, target: str) -> McapRecorder:
        recorder = McapRecorder(target, prefix=NODE_NAME)
        try:
            subs = (self._sub_threats, self._sub_poses, self._sub_start, self._sub_goal)
            pubs = (self._pub_initial, self._pub_path, self._pub_network, self._pub_info)
            for endpoint in subs + pubs:
                recorder.add_topic(endpoint.topic_name, _type_name(endpoint.msg_type),
                                   endpoint.qos_profile)
            recorder.add_topic(PARAMETER_EVENTS_TOPIC, 'rcl_interfaces/msg/ParameterEvent',
                               PARAMETER_EVENTS_QOS)
            # The full parameter set first, so the recording alone says how the node was set.
            event = self._parameter_event()
            event.new_parameters = [self.get_parameter(n).to_parameter_msg()
                                    for n in PARAMETER_DEFAULTS]
            recorder.write(PARAMETER_EVENTS_TOPIC, event, log_time_ns=self._now_ns())
        except RecordingError:
            recorder.close()
            raise
        self.get_logger().info(f'recording inputs and outputs to {recorder.path}')
        return recorder

    def _close_recorder(self) -> None:
        recorder, self._recorder = self._recorder, None
        if recorder is None:
            return
        try:
            recorder.close()
            self.get_logger().info(
                f'closed recording {recorder.path} ({recorder.message_count} messages)')
        except RecordingError as exc:
            self.get_logger().error(f'recording: {exc}')

    def _parameter_event(self) -> ParameterEvent:
        return ParameterEvent(stamp=self.get_clock().now().to_msg(),
                              node=self.get_fully_qualified_name())

    def _record_parameter_event(self, params: Sequence[Parameter]) -> None:
        if self._recorder is None:
            return
        event = self._parameter_event()
        event.changed_parameters = [p.to_parameter_msg() for p in params]
        self._record(PARAMETER_EVENTS_TOPIC, event)

    def _record(self, topic: str, msg: object) -> None:
        if self._recorder is None:
            return
        try:
            self._recorder.write(topic, msg, log_time_ns=self._now_ns())
        except RecordingError as exc:
            # Disk full or similar: stop recording rather than fail every callback.
            self.get_logger().error(f'recording stopped: {exc}')
            self._close_recorder()

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    # -- inputs ----------------------------------------------------------------------

    def _on_threats(self, msg: PointCloud2) -> None:
        def apply() -> None:
            limit = self._settings.max_threats
            count = int(msg.width) * int(msg.height)
            if count > limit:
                raise InputError(f'PointCloud2 has {count} threats, more than '
                                 f'max_threats={limit}')
            positions, intensities = threats_from_pointcloud2(msg, self._settings.frame_id)
            self._set_threats(positions, intensities)
        self._receive(self._sub_threats.topic_name, msg, apply)

    def _on_threat_poses(self, msg: PoseArray) -> None:
        def apply() -> None:
            limit = self._settings.max_threats
            if len(msg.poses) > limit:
                raise InputError(f'PoseArray has {len(msg.poses)} threats, more than '
                                 f'max_threats={limit}')
            positions, intensities = threats_from_pose_array(
                msg, self._settings.frame_id, self._settings.default_intensity)
            self._set_threats(positions, intensities)
        self._receive(self._sub_poses.topic_name, msg, apply)

    @property
    def _known_threats(self) -> ThreatField:
        return _NO_THREATS if self._threats is None else self._threats

    def _set_threats(self, positions: NDArray, intensities: NDArray) -> None:
        field = ThreatField.from_arrays(positions, intensities)
        check_endpoints(self._start, self._goal, self._settings.box, field)
        self._threats = field

    def _on_start(self, msg: PoseStamped) -> None:
        def apply() -> None:
            start = point_from_pose_stamped(msg, self._settings.frame_id, 'start')
            check_endpoints(start, self._goal, self._settings.box,
                            self._known_threats)
            self._start = start
        self._receive(self._sub_start.topic_name, msg, apply)

    def _on_goal(self, msg: PoseStamped) -> None:
        def apply() -> None:
            goal = point_from_pose_stamped(msg, self._settings.frame_id, 'goal_pose')
            check_endpoints(self._start, goal, self._settings.box,
                            self._known_threats)
            self._goal = goal
        self._receive(self._sub_goal.topic_name, msg, apply)

    def _receive(self, topic: str, msg, apply: Callable[[], None]) -> None:
        """Record, number and validate one input; `apply` raises InputError to refuse it."""
        self._record(topic, msg)
        self._seq += 1
        self._received += 1
        try:
            apply()
        except InputError as exc:
            self._reject(topic, msg.header.stamp, str(exc))
            return
        except Exception as exc:  # noqa: B902 - no message may stop the node
            self._reject(topic, msg.header.stamp, f'cannot read: {type(exc).__name__}: {exc}')
            return
        self._request_plan(topic, msg.header.stamp)

    def _reject(self, source: str, stamp: Time, reason: str) -> None:
        self._rejected += 1
        message = f'input #{self._seq} on {source} rejected: {reason}'
        self.get_logger().error(message)
        values = self._input_values(self._seq, source, stamp)
        values['error'] = reason
        self._publish(self._pub_info, plan_info_msg('ERROR', message, values, stamp))

    def _request_plan(self, source: str, stamp: Time) -> None:
        if self._threats is None:
            self.get_logger().info(
                f'input #{self._seq} ({source}) stored; no plan until a threat picture '
                'arrives')
            return
        request = _Request(self._seq, source, stamp, self._now_ns(), self._threats,
                           self._start, self._goal, self._settings)
        if self._worker.submit(request):
            self._skipped += 1

    # -- planning (worker thread) ----------------------------------------------------

    def _plan_job(self, request: _Request) -> None:
        outcome = _Outcome(request)
        t0 = time.perf_counter()
        outcome.queue_ms = max(0.0, 1e-6 * (self._now_ns() - request.received_ns))
        s = request.settings
        try:
            result = plan(request.threats, request.start, request.goal, s.box, s.config)
            t1 = time.perf_counter()
            outcome.plan_ms = 1e3 * (t1 - t0)
            outcome.result = result
            outcome.initial_path = path_to_msg(result.initial_path, s.frame_id, request.stamp)
            outcome.path = path_to_msg(result.path, s.frame_id, request.stamp)
        except (InputError, PlanningError) as exc:
            outcome.error = str(exc)
        except Exception as exc:  # noqa: B902 - a planner bug must not kill the worker
            outcome.error = f'planner failed: {type(exc).__name__}: {exc}'
        if outcome.error is not None:
            self._hand_over('error', outcome)
            return
        # The paths go out before the markers are built: for 1000 threats the MarkerArray
        # takes ~0.1 s, which a path follower should not wait for.
        self._hand_over('paths', outcome)
        try:
            outcome.network = plan_markers(result, request.threats, s.box, s.frame_id,
                                           request.stamp)
        except Exception as exc:  # noqa: B902 - a drawing bug must not lose the plan
            outcome.network_error = f'{type(exc).__name__}: {exc}'
        outcome.messages_ms = 1e3 * (time.perf_counter() - t1)
        self._hand_over('done', outcome)

    def _hand_over(self, phase: str, outcome: _Outcome) -> None:
        """Queue a phase of a plan for the executor thread and wake it."""
        with self._outcome_lock:
            self._outcomes.append((phase, outcome))
        try:
            self._guard.trigger()
        except Exception:  # noqa: B902 - the node may be torn down while a plan ran
            pass

    # -- outputs (executor thread) ---------------------------------------------------

    def _publish(self, publisher, msg) -> None:
        publisher.publish(msg)
        self._record(publisher.topic_name, msg)

    def _input_values(self, seq: int, source: str, stamp: Time) -> dict[str, object]:
        return input_values(seq, source, stamp, self._settings.frame_id, self._received,
                            self._rejected, self._skipped, self._plans)

    def _publish_outcomes(self) -> None:
        while True:
            with self._outcome_lock:
                if not self._outcomes or self._closed:
                    return
                phase, outcome = self._outcomes.popleft()
            if phase == 'paths':
                self._publish(self._pub_initial, outcome.initial_path)
                self._publish(self._pub_path, outcome.path)
            elif phase == 'done':
                self._publish_plan_done(outcome)
            else:
                self._publish_plan_error(outcome)

    def _publish_plan_error(self, outcome: _Outcome) -> None:
        req = outcome.request
        message = f'plan for input #{req.seq} ({req.source}) failed: {outcome.error}'
        self.get_logger().error(message)
        values = self._input_values(req.seq, req.source, req.stamp)
        values['error'] = outcome.error
        self._publish(self._pub_info, plan_info_msg('ERROR', message, values, req.stamp))

    def _publish_plan_done(self, outcome: _Outcome) -> None:
        req = outcome.request
        result = outcome.result
        self._plans += 1
        info = plan_done_info(self._input_values(req.seq, req.source, req.stamp), result,
                              len(req.threats), req.stamp, outcome.queue_ms, outcome.plan_ms,
                              outcome.messages_ms, outcome.network_error)
        if outcome.network is not None:
            self._publish(self._pub_network, outcome.network)
        else:
            self.get_logger().warning(f'input #{req.seq}: network markers not drawn: '
                                      f'{outcome.network_error}')
        self._publish(self._pub_info, info)
        self.get_logger().info(info.status[0].message)

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
        self._close_recorder()


def _type_name(msg_type: type) -> str:
    return f'{msg_type.__module__.split(".")[0]}/msg/{msg_type.__name__}'


def input_values(seq: int, source: str, stamp: Time, frame_id: str, received: int,
                 rejected: int, skipped: int, plans: int) -> dict[str, object]:
    """Return the ``plan_info`` values naming an input and the node's counters.

    Parameters
    ----------
    seq : int
        Input sequence number.
    source : str
        Topic of the input, or ``'parameters'``.
    stamp : builtin_interfaces.msg.Time
        The input's stamp.
    frame_id : str
        Frame of the outputs.
    received, rejected, skipped, plans : int
        Counters of inputs received, rejected and skipped, and of plans completed.

    Returns
    -------
    dict[str, object]
        Keys in ``plan_info`` order.

    """
    return {
        'input_seq': seq,
        'input_source': source,
        'input_stamp_ns': stamp_to_ns(stamp),
        'frame_id': frame_id,
        'inputs_received': received,
        'inputs_rejected': rejected,
        'inputs_skipped': skipped,
        'plans_completed': plans,
    }


def plan_markers(result: PlanResult, threats: ThreatField, box: Box, frame_id: str,
                 stamp: Time) -> MarkerArray:
    """Draw a plan's threats, mesh, network and paths, sized to the flight box.

    Parameters
    ----------
    result : PlanResult
        The plan.
    threats : ThreatField
        The threats it was planned through.
    box : Box
        Flight box (sets the marker sizes).
    frame_id : str
        Frame of the markers.
    stamp : builtin_interfaces.msg.Time
        Stamp of the markers (the input's).

    Returns
    -------
    MarkerArray
        What the node publishes on ``network``.

    """
    scale = box.diagonal / math.sqrt(3.0) / 100.0
    net = result.network
    return network_markers(
        threats.positions, threats.intensities,
        vertices=net.vertices, delaunay_edges=net.delaunay_edges(), nodes=net.nodes,
        network_edges=net.edges, initial_path=result.initial_path,
        path=result.path, frame_id=frame_id, stamp=stamp,
        threat_diameter=4.0 * scale, node_diameter=scale, line_width=0.2 * scale)


def plan_done_info(values: Mapping[str, object], result: PlanResult, n_threats: int,
                   stamp: Time, queue_ms: float, plan_ms: float, messages_ms: float,
                   network_error: Optional[str] = None) -> DiagnosticArray:
    """Build the ``plan_info`` of a finished plan (OK, or WARN if an angle limit is broken).

    Parameters
    ----------
    values : Mapping[str, object]
        The input's values (:func:`input_values`); the result's are appended.
    result : PlanResult
        The plan.
    n_threats : int
        Threats planned through.
    stamp : builtin_interfaces.msg.Time
        The input's stamp.
    queue_ms, plan_ms, messages_ms : float
        Wait before planning, planning and marker drawing times [ms].
    network_error : str, optional
        Why the markers could not be drawn.

    Returns
    -------
    DiagnosticArray
        The message; its status message is the node's log line.

    """
    values = dict(values)
    values.update(_result_values(result, n_threats))
    values['queue_ms'] = queue_ms
    values['plan_wall_ms'] = plan_ms
    values['messages_ms'] = messages_ms
    if network_error is not None:
        values['network_error'] = network_error
    status = 'OK' if result.feasible else 'WARN'
    message = (f'plan for input #{values["input_seq"]} ({values["input_source"]}): '
               f'J={result.cost.J:.6g} through {n_threats} threats in {plan_ms:.0f} ms'
               + ('' if result.feasible else '; violates the pitch or turn limit'))
    return plan_info_msg(status, message, values, stamp)


def _result_values(result: PlanResult, n_threats: int) -> dict[str, object]:
    values: dict[str, object] = {
        'method': result.method,
        'w': result.w,
        'threats': n_threats,
        'J': result.cost.J,
        'J_L': result.cost.J_L,
        'J_R': result.cost.J_R,
        'initial_J': result.initial_cost.J,
        'initial_J_L': result.initial_cost.J_L,
        'initial_J_R': result.initial_cost.J_R,
        'nodes': result.network.n_nodes,
        'edges': result.network.n_edges,
        'entry': result.entry,
        'exit': result.exit,
        'k': result.k,
        'feasible': result.feasible,
        'max_pitch_deg': result.angles.max_pitch_deg,
        'max_turn_deg': result.angles.max_turn_deg,
        'path_points': len(result.path),
        'initial_path_points': len(result.initial_path),
    }
    values.update(result.timings_ms)
    return values


# ---------------------------------------------------------------------------- main


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
