"""Record offline plans as the node would, and replay recordings as regression tests.

Three jobs, all on the MCAP files :mod:`threat_planner.bag.writer` writes:

* :func:`record_plan` plans a scenario without ROS and records it as a planner node with
  parameter ``record`` set would have: the full parameter set as a
  ``rcl_interfaces/msg/ParameterEvent`` on ``/parameter_events``, then the inputs
  ``start``, ``goal_pose`` and ``threats`` (a float32 PointCloud2, which is what the plan
  is computed from), then the outputs ``initial_path``, ``path``, ``network`` and
  ``plan_info``, with the node's topic names, types and QoS, built by the node's own
  message code. ``threat-planner plan SCENARIO --record OUT.mcap`` calls it.
* :func:`load_bag` and :func:`replay_bag` read a recording's inputs in time order, rebuild
  the node's state after each one (threat picture, start, goal, parameters; a refused
  input leaves the state as it was, as in the node), re-plan each state the recording has
  a ``plan_info`` for and compare the new plan with the recorded one: the ``initial_path``
  node sequence, the largest distance between ``path`` points and the relative difference
  of J. Outputs are matched to inputs through ``plan_info``'s ``input_seq`` (the offset
  between the node's numbering and the recording's is found from ``input_source`` and
  ``input_stamp_ns``, so a recording started at run time works too) and the paths through
  their header stamp. ``threat-planner replay BAG`` calls it.
* :func:`play_live` publishes a recording's inputs to a running node with their recorded
  timing (scaled by a rate factor) and sets its recorded parameters through the node's
  parameter services: ``ros2 bag play`` for this node without ros2cli.

The planner is deterministic, so a recording replays to the same plans to the last bit on
the machine that made it; the default tolerance (1e-6 m and 1e-6 relative) absorbs the
rounding differences another CPU or BLAS may bring. When the algorithm changes on
purpose, recordings compared against must be recorded again (see
``bench/record_regression_bags.py``).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field, fields, replace
import math
import os
from pathlib import Path
import threading
import time
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

from geometry_msgs.msg import PoseStamped
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import ParameterEvent

from threat_planner.ros.conversions import (ns_to_stamp, path_from_msg, path_to_msg,
                                            PLAN_STATUS_NAME, plan_info_msg, plan_info_values,
                                            point_from_pose_stamped, pointcloud2_from_threats,
                                            stamp_to_ns, threats_from_pointcloud2,
                                            threats_from_pose_array)
from threat_planner.errors import (InputError, PlanningError, RecordingError, ThreatPlannerError)
from threat_planner.core.planner import check_endpoints, plan, PlannerConfig, PlanResult
from threat_planner.ros.node import (input_values, LATCHED, NODE_NAME, NodeSettings,
                                     PARAMETER_DEFAULTS, PARAMETER_EVENTS_QOS,
                                     PARAMETER_EVENTS_TOPIC, plan_done_info, plan_markers,
                                     POSE_INPUT, settings_from_parameters, THREAT_INPUT)
from threat_planner.bag import (McapRecorder, read_ros_messages, RecordedMessage, recorded_topics)
from threat_planner.core.scenario import Scenario
from threat_planner.core.threats import ThreatField

__all__ = ['Bag', 'BagInput', 'BagPlan', 'DEFAULT_TOLERANCE', 'LiveResult', 'ReplayReport',
           'ReplayRow', 'load_bag', 'play_live', 'record_plan', 'replay_bag']

#: Largest path point distance [m] and relative J difference accepted by default.
DEFAULT_TOLERANCE = 1e-6

#: The node's inputs: topic name (relative) -> (type, subscription QoS).
INPUT_TOPICS = {
    'threats': ('sensor_msgs/msg/PointCloud2', THREAT_INPUT),
    'threat_poses': ('geometry_msgs/msg/PoseArray', THREAT_INPUT),
    'start': ('geometry_msgs/msg/PoseStamped', POSE_INPUT),
    'goal_pose': ('geometry_msgs/msg/PoseStamped', POSE_INPUT),
}
#: The node's outputs: topic name (relative) -> (type, publisher QoS).
OUTPUT_TOPICS = {
    'initial_path': ('nav_msgs/msg/Path', LATCHED),
    'path': ('nav_msgs/msg/Path', LATCHED),
    'network': ('visualization_msgs/msg/MarkerArray', LATCHED),
    'plan_info': ('diagnostic_msgs/msg/DiagnosticArray', LATCHED),
}
_THREAT_TOPICS = ('threats', 'threat_poses')
_PARAMETER_EVENT_TYPE = 'rcl_interfaces/msg/ParameterEvent'
_CONFIG_FIELDS = tuple(n for n in PARAMETER_DEFAULTS if n in PlannerConfig.__dataclass_fields__)
_PARAMETERS = 'parameters'
_LEVEL_NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}


def _now_ns() -> int:
    return time.time_ns()


def _level_name(level) -> str:
    # DiagnosticStatus.level is a ``byte``: rclpy gives it as a 1-byte bytes object.
    if isinstance(level, (bytes, bytearray)):
        level = level[0] if level else -1
    return _LEVEL_NAMES.get(int(level), str(level))


# ------------------------------------------------------------------ offline recording


def _declared(name: str, value: object) -> object:
    """Give a value the type its parameter is declared with (a float k, an int n_points)."""
    default = PARAMETER_DEFAULTS[name]
    if isinstance(default, bool):
        return bool(value)
    if isinstance(default, int):
        return int(value)
    if isinstance(default, float):
        return float(value)
    return value


def _scenario_parameters(scenario: Scenario, config: PlannerConfig,
                         record: str) -> Dict[str, object]:
    defaults = PlannerConfig()
    for f in fields(PlannerConfig):
        if f.name not in _CONFIG_FIELDS and getattr(config, f.name) != getattr(defaults, f.name):
            raise RecordingError(
                f'{f.name}={getattr(config, f.name)!r} is not a node parameter, so a '
                'recording cannot say how the plan was made')
    values = dict(PARAMETER_DEFAULTS)
    for name in _CONFIG_FIELDS:
        values[name] = _declared(name, getattr(config, name))
    box = scenario.box
    values['bounds'] = [float(v) for v in np.concatenate([box.lo, box.hi])]
    values['start'] = [float(v) for v in scenario.start]
    values['goal'] = [float(v) for v in scenario.goal]
    values['frame_id'] = scenario.frame_id
    values['record'] = record
    return values


def _pose_msg(xyz: NDArray, frame_id: str, stamp_ns: int) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
    msg.pose.orientation.w = 1.0
    return msg


def record_plan(scenario: Scenario, config: PlannerConfig, target, *,
                progress: Optional[Callable[[int, int], None]] = None
                ) -> Tuple[PlanResult, Path]:
    """Plan a scenario and record it as a planner node (namespace ``/``) would have.

    The recording holds what a node started with the scenario's bounds, start, goal and
    frame as parameters and ``config``'s settings would record when sent the scenario's
    start, goal and threats (in that order): the parameter event listing every
    parameter, the three inputs, then the four outputs of the one plan. The plan is made
    from the threats as the PointCloud2 carries them (float32), exactly as the node would,
    so it may differ from a plan of the float64 scenario in the last digits.

    Parameters
    ----------
    scenario : Scenario
        The planning problem.
    config : PlannerConfig
        Planner settings; only fields that are node parameters may differ from the
        defaults.
    target : str or os.PathLike
        A ``.mcap`` file, or a folder in which a rosbag2 bag directory is created.
    progress : callable, optional
        ``progress(done, total)`` for long sweeps, as :func:`threat_planner.core.planner.plan`.

    Returns
    -------
    result : PlanResult
        The plan.
    path : Path
        The ``.mcap`` file written.

    Raises
    ------
    RecordingError
        If the file cannot be written or ``config`` cannot be expressed as parameters.
    InputError, PlanningError
        As :func:`threat_planner.core.planner.plan`.

    """
    from rclpy.parameter import Parameter

    config.validated()
    values = _scenario_parameters(scenario, config, str(target))
    settings = settings_from_parameters(values)
    frame = settings.frame_id
    with McapRecorder(target, prefix=NODE_NAME) as rec:
        for name, (type_name, qos) in {**INPUT_TOPICS, **OUTPUT_TOPICS}.items():
            rec.add_topic(f'/{name}', type_name, qos)
        rec.add_topic(PARAMETER_EVENTS_TOPIC, _PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_QOS)
        t = _now_ns()
        event = ParameterEvent(stamp=ns_to_stamp(t), node=f'/{NODE_NAME}')
        event.new_parameters = [Parameter(n, value=v).to_parameter_msg()
                                for n, v in values.items()]
        rec.write(PARAMETER_EVENTS_TOPIC, event, log_time_ns=t)

        # The inputs, as threat_publisher sends them: start, goal, then the picture.
        ends = []
        for topic, xyz in (('start', scenario.start), ('goal_pose', scenario.goal)):
            msg = _pose_msg(xyz, frame, _now_ns())
            rec.write(f'/{topic}', msg, log_time_ns=stamp_to_ns(msg.header.stamp))
            ends.append(point_from_pose_stamped(msg, frame, topic))
        start, goal = ends
        cloud_ns = _now_ns()
        stamp = ns_to_stamp(cloud_ns)
        cloud = pointcloud2_from_threats(scenario.threats.positions,
                                         scenario.threats.intensities, frame, stamp)
        rec.write('/threats', cloud, log_time_ns=cloud_ns)
        positions, intensities = threats_from_pointcloud2(cloud, frame)
        threats = ThreatField.from_arrays(positions, intensities)

        seq = 3  # the node's number of the threats input, after start and goal_pose
        t0 = time.perf_counter()
        queue_ms = 1e-6 * (_now_ns() - cloud_ns)
        try:
            result = plan(threats, start, goal, settings.box, settings.config,
                          progress=progress)
        except (InputError, PlanningError) as exc:
            # What the node publishes for a plan that fails, then the error as usual.
            values = input_values(seq, '/threats', stamp, frame, seq, 0, 0, 0)
            values['error'] = str(exc)
            rec.write('/plan_info', plan_info_msg(
                'ERROR', f'plan for input #{seq} (/threats) failed: {exc}', values, stamp),
                log_time_ns=_now_ns())
            raise
        t1 = time.perf_counter()
        rec.write('/initial_path', path_to_msg(result.initial_path, frame, stamp),
                  log_time_ns=_now_ns())
        rec.write('/path', path_to_msg(result.path, frame, stamp), log_time_ns=_now_ns())
        markers = plan_markers(result, threats, settings.box, frame, stamp)
        messages_ms = 1e3 * (time.perf_counter() - t1)
        rec.write('/network', markers, log_time_ns=_now_ns())
        info = plan_done_info(input_values(seq, '/threats', stamp, frame, seq, 0, 0, 1),
                              result, len(threats), stamp, queue_ms, 1e3 * (t1 - t0),
                              messages_ms)
        rec.write('/plan_info', info, log_time_ns=_now_ns())
        written = rec.path
    return result, written


# ---------------------------------------------------------------------- reading bags


@dataclass
class BagInput:
    """One input the node received (a message, or an accepted parameter change).

    Attributes
    ----------
    index : int
        1-based position among the recording's inputs.
    source : str
        Full topic name, or ``'parameters'`` (as ``plan_info``'s ``input_source``).
    kind : str
        ``'threats'``, ``'threat_poses'``, ``'start'``, ``'goal_pose'`` or ``'parameters'``.
    log_time_ns : int
        Receive time [ns].
    stamp_ns : int
        Header stamp [ns] (a parameter event's stamp for parameter changes).
    msg : object
        The rclpy message (a ParameterEvent for parameter changes).

    """

    index: int
    source: str
    kind: str
    log_time_ns: int
    stamp_ns: int
    msg: object


@dataclass
class BagPlan:
    """One recorded ``plan_info`` and the paths published for it.

    Attributes
    ----------
    index : int
        1-based position among the recording's ``plan_info`` messages.
    log_time_ns : int
        Publish time [ns].
    level : str
        ``'OK'``, ``'WARN'`` or ``'ERROR'``.
    message : str
        The status message.
    values : dict[str, str]
        The key/values.
    initial_path, path : NDArray or None
        The ``initial_path`` and ``path`` points recorded for the same input, if any.

    """

    index: int
    log_time_ns: int
    level: str
    message: str
    values: Dict[str, str]
    initial_path: Optional[NDArray] = None
    path: Optional[NDArray] = None

    @property
    def seq(self) -> int:
        """The node's input sequence number."""
        return int(self.values.get('input_seq', -1))

    @property
    def source(self) -> str:
        """Topic of the input, or ``'parameters'``."""
        return self.values.get('input_source', '')

    @property
    def stamp_ns(self) -> int:
        """Stamp of the input [ns]."""
        return int(self.values.get('input_stamp_ns', -1))

    @property
    def outcome(self) -> str:
        """``'OK'`` or ``'WARN'`` for a plan, ``'rejected'`` or ``'failed'`` for an error."""
        if self.level != 'ERROR':
            return self.level
        return 'rejected' if ' rejected: ' in self.message else 'failed'


@dataclass
class Bag:
    """A recording of the planner node, read for replay.

    Attributes
    ----------
    path : Path
        The file or bag directory.
    namespace : str
        Namespace of the node's topics (``''`` for ``/threats``).
    node_name : str
        Fully qualified name of the node that recorded it.
    parameters : dict[str, object]
        The node's parameters when the recording started (defaults if not recorded).
    parameters_recorded : bool
        Whether the recording holds the full parameter event.
    inputs : list of BagInput
        The inputs in time order.
    plans : list of BagPlan
        The ``plan_info`` outputs in time order.
    initial_parameter_msgs : list
        The ``rcl_interfaces/msg/Parameter`` messages of the full parameter event.

    """

    path: Path
    namespace: str
    node_name: str
    parameters: Dict[str, object]
    parameters_recorded: bool
    inputs: List[BagInput]
    plans: List[BagPlan]
    initial_parameter_msgs: list = field(default_factory=list)

    def topic(self, name: str) -> str:
        """Full name of the node's topic `name` in this recording."""
        return f'{self.namespace}/{name}'


def _parameter_values(params) -> Dict[str, object]:
    from rclpy.parameter import parameter_value_to_python
    values = {}
    for p in params:
        value = parameter_value_to_python(p.value)
        if not isinstance(value, (str, bytes)) and hasattr(value, '__len__'):
            value = list(value)
        values[p.name] = value
    return values


def _find_namespace(path: Path, topics: Mapping[str, str]) -> str:
    found = []
    for topic, type_name in topics.items():
        for name in _THREAT_TOPICS:
            if topic == f'/{name}' or topic.endswith(f'/{name}'):
                expected = INPUT_TOPICS[name][0]
                if type_name != expected:
                    raise RecordingError(
                        f'{path}: topic {topic} is a {type_name or "schema-less channel"}, '
                        f'not the {expected} the planner node takes')
                found.append(topic[:-len(name) - 1])
    namespaces = sorted(set(found))
    if not namespaces:
        listed = ', '.join(sorted(topics)) or 'none'
        raise RecordingError(
            f'{path}: no threat topic (.../threats sensor_msgs/msg/PointCloud2 or '
            f'.../threat_poses geometry_msgs/msg/PoseArray); topics: {listed}')
    if len(namespaces) > 1:
        raise RecordingError(f'{path}: threat topics of several planner namespaces: '
                             f'{", ".join(n or "/" for n in namespaces)}')
    return namespaces[0]


def _points_before(recorded: Sequence[RecordedMessage], stamp_ns: int,
                   log_time_ns: int) -> Optional[NDArray]:
    found = None
    for m in recorded:
        if m.log_time_ns > log_time_ns:
            break
        if stamp_to_ns(m.msg.header.stamp) == stamp_ns:
            found = m
    return None if found is None else path_from_msg(found.msg)


def load_bag(path, *, tolerant: bool = False) -> Bag:
    """Read a planner node's recording: its parameters, inputs and plan outputs.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.mcap`` file or a rosbag2 bag directory.
    tolerant : bool
        Accept a file cut off by a crash, reading up to its last complete chunk.

    Returns
    -------
    Bag
        The recording.

    Raises
    ------
    RecordingError
        One line naming the file: missing, not MCAP, truncated (unless `tolerant`),
        corrupt, a channel in an unknown encoding or of a type that is not installed, no
        threat topic, or a node topic of the wrong type.

    """
    path = Path(path)
    topics = recorded_topics(path, tolerant=tolerant)
    ns = _find_namespace(path, topics)
    wanted = {f'{ns}/{name}': type_name
              for name, (type_name, _) in {**INPUT_TOPICS, **OUTPUT_TOPICS}.items()}
    for topic, type_name in wanted.items():
        if topic in topics and topics[topic] != type_name:
            raise RecordingError(f'{path}: topic {topic} is a {topics[topic]}, not the '
                                 f'{type_name} the planner node uses')
    if PARAMETER_EVENTS_TOPIC in topics and topics[PARAMETER_EVENTS_TOPIC] != \
            _PARAMETER_EVENT_TYPE:
        raise RecordingError(f'{path}: {PARAMETER_EVENTS_TOPIC} is a '
                             f'{topics[PARAMETER_EVENTS_TOPIC]}, not a {_PARAMETER_EVENT_TYPE}')
    read = [t for t in list(wanted) + [PARAMETER_EVENTS_TOPIC] if t in topics]
    messages = sorted(read_ros_messages(path, tolerant=tolerant, topics=read),
                      key=lambda m: m.log_time_ns)

    node_name = f'{ns}/{NODE_NAME}'
    parameters = dict(PARAMETER_DEFAULTS)
    recorded_params = False
    initial_msgs: list = []
    by_topic: Dict[str, List[RecordedMessage]] = collections.defaultdict(list)
    inputs: List[BagInput] = []
    kinds = {f'{ns}/{name}': name for name in INPUT_TOPICS}
    for m in messages:
        by_topic[m.topic].append(m)
        if m.topic == PARAMETER_EVENTS_TOPIC:
            event = m.msg
            names = {p.name for p in event.new_parameters}
            if not recorded_params and {'method', 'bounds', 'record'} <= names:
                # The node's full parameter set, written when its recording started.
                node_name, recorded_params = event.node, True
                parameters.update(_parameter_values(event.new_parameters))
                initial_msgs = list(event.new_parameters)
            elif event.node == node_name and event.changed_parameters:
                inputs.append(BagInput(len(inputs) + 1, _PARAMETERS, _PARAMETERS,
                                       m.log_time_ns, stamp_to_ns(event.stamp), event))
        elif m.topic in kinds:
            inputs.append(BagInput(len(inputs) + 1, m.topic, kinds[m.topic], m.log_time_ns,
                                   stamp_to_ns(m.msg.header.stamp), m.msg))
    plans = []
    for m in by_topic.get(f'{ns}/plan_info', []):
        try:
            values = plan_info_values(m.msg)
        except InputError:
            continue  # some other node's diagnostics
        status = next(d for d in m.msg.status if d.name == PLAN_STATUS_NAME)
        plan_ = BagPlan(len(plans) + 1, m.log_time_ns, _level_name(status.level),
                        status.message, values)
        if plan_.level != 'ERROR':
            plan_.initial_path = _points_before(by_topic.get(f'{ns}/initial_path', []),
                                                plan_.stamp_ns, m.log_time_ns)
            plan_.path = _points_before(by_topic.get(f'{ns}/path', []), plan_.stamp_ns,
                                        m.log_time_ns)
        plans.append(plan_)
    return Bag(path, ns, node_name, parameters, recorded_params, inputs, plans, initial_msgs)


# ------------------------------------------------------------------- node state


@dataclass(frozen=True)
class _State:
    """What the node holds after an input: the plan request it would make."""

    values: Mapping[str, object]
    settings: NodeSettings
    threats: Optional[ThreatField]
    start: NDArray
    goal: NDArray


_NO_THREATS = ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0))


def _apply(state: _State, inp: BagInput) -> _State:
    """Apply one input as the node does; raise InputError with the node's reason."""
    s = state.settings
    known = state.threats if state.threats is not None else _NO_THREATS
    msg = inp.msg
    if inp.kind == 'threats':
        count = int(msg.width) * int(msg.height)
        if count > s.max_threats:
            raise InputError(f'PointCloud2 has {count} threats, more than '
                             f'max_threats={s.max_threats}')
        positions, intensities = threats_from_pointcloud2(msg, s.frame_id)
    elif inp.kind == 'threat_poses':
        if len(msg.poses) > s.max_threats:
            raise InputError(f'PoseArray has {len(msg.poses)} threats, more than '
                             f'max_threats={s.max_threats}')
        positions, intensities = threats_from_pose_array(msg, s.frame_id, s.default_intensity)
    elif inp.kind == 'start':
        start = point_from_pose_stamped(msg, s.frame_id, 'start')
        check_endpoints(start, state.goal, s.box, known)
        return replace(state, start=start)
    elif inp.kind == 'goal_pose':
        goal = point_from_pose_stamped(msg, s.frame_id, 'goal_pose')
        check_endpoints(state.start, goal, s.box, known)
        return replace(state, goal=goal)
    else:
        changes = _parameter_values(msg.changed_parameters)
        values = {**state.values, **changes}
        settings = settings_from_parameters(values)
        return replace(state, values=values, settings=settings,
                       start=settings.start if 'start' in changes else state.start,
                       goal=settings.goal if 'goal' in changes else state.goal)
    field_ = ThreatField.from_arrays(positions, intensities)
    check_endpoints(state.start, state.goal, s.box, field_)
    return replace(state, threats=field_)


def _states(bag: Bag) -> List[Tuple[_State, Optional[str]]]:
    """Return the state after each input and, for a refused input, the node's reason."""
    settings = settings_from_parameters(bag.parameters)
    state = _State(dict(bag.parameters), settings, None, settings.start, settings.goal)
    out = []
    for inp in bag.inputs:
        try:
            state = _apply(state, inp)
            reason = None
        except InputError as exc:
            reason = str(exc)
        except Exception as exc:  # noqa: B902 - the node refuses any unreadable input
            reason = f'cannot read: {type(exc).__name__}: {exc}'
        out.append((state, reason))
    return out


def _seq_offset(bag: Bag) -> int:
    """Offset between the node's input numbers and the recording's (0 if it began with it)."""
    keyed = collections.defaultdict(list)
    for inp in bag.inputs:
        keyed[(inp.source, inp.stamp_ns)].append(inp.index)
    candidates = {0}
    for p in bag.plans:
        candidates.update(p.seq - k for k in keyed.get((p.source, p.stamp_ns), ()))

    def score(offset: int) -> int:
        hits = 0
        for p in bag.plans:
            k = p.seq - offset
            if 1 <= k <= len(bag.inputs):
                inp = bag.inputs[k - 1]
                hits += inp.source == p.source and (
                    inp.source == _PARAMETERS or inp.stamp_ns == p.stamp_ns)
        return hits
    return max(sorted(candidates, key=abs), key=score)


# -------------------------------------------------------------------------- replay


@dataclass
class ReplayRow:
    """The comparison for one recorded ``plan_info``.

    Attributes
    ----------
    index : int
        1-based position of the ``plan_info`` in the recording.
    seq, source, stamp_ns : int, str, int
        The input it answers: the node's number, topic (or ``'parameters'``), stamp.
    log_time_ns : int
        When the ``plan_info`` was recorded.
    recorded, replayed : str
        Outcome: ``'OK'``, ``'WARN'``, ``'rejected'`` or ``'failed'``.
    method : str
        Method of the re-plan.
    j_recorded, j_replayed, j_rel : float or None
        J of both plans and their relative difference.
    max_dp : float or None
        Largest distance between corresponding ``path`` points [m].
    nodes_match : bool or None
        Whether the ``initial_path`` node sequences (and entry and exit) agree.
    ok : bool
        Whether everything agrees within the tolerance.
    note : str
        What differs.

    """

    index: int
    seq: int
    source: str
    stamp_ns: int
    log_time_ns: int
    recorded: str
    replayed: str = '-'
    method: str = ''
    j_recorded: Optional[float] = None
    j_replayed: Optional[float] = None
    j_rel: Optional[float] = None
    max_dp: Optional[float] = None
    nodes_match: Optional[bool] = None
    ok: bool = True
    note: str = ''


@dataclass
class ReplayReport:
    """Result of :func:`replay_bag`.

    Attributes
    ----------
    bag : Bag
        The recording.
    tolerance : float
        Tolerance used.
    overrides : dict[str, object]
        Planner settings used instead of the recorded ones.
    rows : list of ReplayRow
        One per recorded ``plan_info``.

    """

    bag: Bag
    tolerance: float
    overrides: Dict[str, object]
    rows: List[ReplayRow]

    @property
    def first_difference(self) -> Optional[ReplayRow]:
        """The first row outside the tolerance, or None."""
        return next((r for r in self.rows if not r.ok), None)

    @property
    def ok(self) -> bool:
        """Whether every plan replayed within the tolerance."""
        return self.first_difference is None

    def difference_text(self) -> str:
        """One line naming the first message that differs (empty if none)."""
        row = self.first_difference
        if row is None:
            return ''
        bag = self.bag
        topic = bag.topic('plan_info')
        if row.max_dp is not None and row.max_dp > self.tolerance:
            topic = bag.topic('path')
        elif row.nodes_match is False:
            topic = bag.topic('initial_path')
        start = bag.inputs[0].log_time_ns if bag.inputs else row.log_time_ns
        return (f'first difference: {topic} for input #{row.seq} ({row.source}, stamp '
                f'{row.stamp_ns} ns; plan_info #{row.index} of {len(self.rows)}, '
                f'{1e-9 * (row.log_time_ns - start):.3f} s into the recording): {row.note}')

    def table(self) -> str:
        """Return the comparison as a Markdown table."""
        def num(v, fmt):
            return '-' if v is None else format(v, fmt)
        lines = ['| # | input | source | recorded | replayed | method | J recorded | '
                 'J replayed | rel dJ | max dp [m] | nodes | result |',
                 '|---:|---:|---|---|---|---|---:|---:|---:|---:|---|---|']
        for r in self.rows:
            nodes = '-' if r.nodes_match is None else ('same' if r.nodes_match else 'DIFFER')
            result = 'ok' if r.ok else f'DIFFERS: {r.note}'
            lines.append(
                f'| {r.index} | {r.seq} | {r.source} | {r.recorded} | {r.replayed} | '
                f'{r.method or "-"} | {num(r.j_recorded, ".6g")} | {num(r.j_replayed, ".6g")} '
                f'| {num(r.j_rel, ".1e")} | {num(r.max_dp, ".1e")} | {nodes} | {result} |')
        return '\n'.join(lines)

    def summary(self) -> str:
        """One line: how many plans replayed and whether they all matched."""
        n = len(self.rows)
        skipped = sum(r.replayed == 'skipped' for r in self.rows)
        if self.ok:
            n -= skipped
            return (f'{n} plan{"s" * (n != 1)} replayed, all within tolerance '
                    f'{self.tolerance:g}' + (f'; {skipped} skipped (threat picture not '
                                             'in the recording)' if skipped else ''))
        bad = sum(not r.ok for r in self.rows)
        return f'REGRESSION: {bad} of {n} plans differ (tolerance {self.tolerance:g}); ' + \
            self.difference_text()

    def markdown(self) -> str:
        """Return a Markdown report: the recording, the settings, the table, the verdict."""
        bag = self.bag
        over = ', '.join(f'{k}={v!r}' for k, v in self.overrides.items()) or 'none'
        params = 'recorded' if bag.parameters_recorded else 'not recorded (node defaults)'
        return '\n'.join([
            f'# Replay of {bag.path.name}', '',
            f'- recording: `{bag.path}`',
            f'- node: `{bag.node_name}`; {len(bag.inputs)} inputs, {len(bag.plans)} '
            f'plan_info messages; parameters {params}',
            f'- overrides: {over}',
            f'- tolerance: {self.tolerance:g} (path points [m], relative J)', '',
            self.table(), '', self.summary(), ''])


def _node_ids(points: NDArray, nodes: NDArray, tol: float) -> List[int]:
    if len(points) == 0 or len(nodes) == 0:
        return [-1] * len(points)
    d = np.linalg.norm(points[:, None, :] - nodes[None, :, :], axis=2)
    idx = d.argmin(axis=1)
    close = d[np.arange(len(points)), idx] <= tol
    return [int(i) if c else -1 for i, c in zip(idx, close)]


def _compare(row: ReplayRow, rec: BagPlan, result: PlanResult, tol: float) -> None:
    notes = []
    row.j_replayed = result.cost.J
    if 'J' in rec.values:
        row.j_recorded = float(rec.values['J'])
        scale = max(abs(row.j_recorded), 1e-12)
        row.j_rel = abs(row.j_replayed - row.j_recorded) / scale
        if not row.j_rel <= tol:
            notes.append(f'J {row.j_recorded:.9g} -> {row.j_replayed:.9g} '
                         f'(relative {row.j_rel:.2e})')
    if rec.path is None:
        notes.append('no path recorded for this input')
    elif rec.path.shape != result.path.shape:
        notes.append(f'path has {len(result.path)} points, recorded {len(rec.path)}')
    else:
        row.max_dp = float(np.max(np.linalg.norm(rec.path - result.path, axis=1)))
        if not row.max_dp <= tol:
            notes.append(f'path points moved up to {row.max_dp:.3g} m')
    if rec.initial_path is None:
        notes.append('no initial_path recorded for this input')
    else:
        nodes = result.network.nodes
        recorded_seq = _node_ids(rec.initial_path[1:-1], nodes, max(tol, 1e-9))
        entry_exit = (int(rec.values.get('entry', result.entry)),
                      int(rec.values.get('exit', result.exit)))
        row.nodes_match = (recorded_seq == list(result.node_sequence)
                           and entry_exit == (result.entry, result.exit))
        if not row.nodes_match:
            notes.append(f'initial path nodes {recorded_seq} (entry {entry_exit[0]}, exit '
                         f'{entry_exit[1]}) -> {list(result.node_sequence)}')
    if row.recorded != row.replayed:
        notes.insert(0, f'status {row.recorded} -> {row.replayed}')
    row.ok = not notes
    row.note = '; '.join(notes)


def replay_bag(bag: Bag, *, tolerance: float = DEFAULT_TOLERANCE,
               overrides: Optional[Mapping[str, object]] = None,
               progress: Optional[Callable[[int, int], None]] = None) -> ReplayReport:
    """Re-plan every input state a recording has a ``plan_info`` for and compare.

    Parameters
    ----------
    bag : Bag
        The recording (:func:`load_bag`).
    tolerance : float
        Largest distance between recorded and re-planned path points [m] and largest
        relative J difference accepted; the ``initial_path`` node sequence and the outcome
        (OK, WARN, rejected, failed) must be the same.
    overrides : Mapping[str, object], optional
        PlannerConfig fields (``method``, ``w``, ...) to use instead of the recorded ones.
    progress : callable, optional
        ``progress(done, total)`` after each plan.

    Returns
    -------
    ReplayReport
        One row per recorded ``plan_info``.

    Raises
    ------
    InputError
        For a negative tolerance or a bad override.
    RecordingError
        If the recording holds no ``plan_info`` to compare with.

    """
    if not (math.isfinite(tolerance) and tolerance >= 0.0):
        raise InputError(f'tolerance: must be finite and >= 0, got {tolerance!r}')
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    if overrides:
        try:
            replace(PlannerConfig(), **overrides).validated()
        except TypeError as exc:
            raise InputError(f'overrides: {exc}') from None
    if not bag.plans:
        raise RecordingError(f'{bag.path}: no plan_info recorded on {bag.topic("plan_info")}'
                             ': nothing to compare')
    states = _states(bag)
    offset = _seq_offset(bag)
    rows = []
    for n, rec in enumerate(bag.plans, 1):
        row = ReplayRow(rec.index, rec.seq, rec.source, rec.stamp_ns, rec.log_time_ns,
                        rec.outcome)
        rows.append(row)
        k = rec.seq - offset
        inp = bag.inputs[k - 1] if 1 <= k <= len(bag.inputs) else None
        if inp is None or inp.source != rec.source:
            row.ok = False
            row.note = f'input #{rec.seq} ({rec.source}) is not in the recording'
        else:
            _replay_one(row, rec, states[k - 1], overrides, tolerance)
        if progress is not None:
            progress(n, len(bag.plans))
    return ReplayReport(bag, tolerance, overrides, rows)


def _replay_one(row: ReplayRow, rec: BagPlan, state_reason: Tuple[_State, Optional[str]],
                overrides: Mapping[str, object], tol: float) -> None:
    state, reason = state_reason
    config = replace(state.settings.config, **overrides)
    row.method = config.method
    if reason is not None:
        row.replayed = 'rejected'
        note = f'refused: {reason}'
    elif state.threats is None:
        # Recording switched on at run time: the picture planned through is not in it.
        row.replayed = 'skipped'
        row.note = 'its threat picture was received before the recording started'
        return
    else:
        try:
            result = plan(state.threats, state.start, state.goal, state.settings.box, config)
        except (InputError, PlanningError) as exc:
            row.replayed = 'failed'
            note = f'failed: {exc}'
        else:
            row.replayed = 'OK' if result.feasible else 'WARN'
            if rec.level == 'ERROR':
                row.ok = False
                row.j_replayed = result.cost.J
                row.note = f'status {row.recorded} -> {row.replayed} ({rec.message})'
                return
            _compare(row, rec, result, tol)
            return
    row.ok = row.recorded == row.replayed
    if not row.ok:
        row.note = f'status {row.recorded} -> {row.replayed} ({note})'


# -------------------------------------------------------------------------- live


@dataclass
class LiveResult:
    """What :func:`play_live` did.

    Attributes
    ----------
    published : int
        Messages published.
    parameters_set : bool
        Whether the recorded parameters were set on the node.
    parameter_changes : int
        Recorded parameter changes applied.
    duration_s : float
        Time from the first to the last input, plus the wait for the answer [s].
    answers : list of dict
        ``plan_info`` values (plus ``level``) the node published for these inputs.
    last_answered : bool or None
        Whether the node answered the last input (None: nothing to wait for).
    namespace, node_name : str
        Where the inputs went.

    """

    published: int
    parameters_set: bool
    parameter_changes: int
    duration_s: float
    answers: List[Dict[str, str]]
    last_answered: Optional[bool]
    namespace: str
    node_name: str


def _normalise_ns(namespace: str) -> str:
    return '/' + namespace.strip('/') if namespace.strip('/') else ''


def _retarget(name: str, old_ns: str, new_ns: Optional[str]) -> str:
    """Move a recorded topic or node name from the recorded namespace to `new_ns`."""
    if new_ns is None:
        return name
    if old_ns and not name.startswith(old_ns + '/'):
        return name
    return _normalise_ns(new_ns) + name[len(old_ns):]


def _wait(condition: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def play_live(bag: Bag, *, rate: float = 1.0, namespace: Optional[str] = None,
              set_parameters: bool = True, overrides: Optional[Mapping[str, object]] = None,
              connect_timeout: float = 30.0, wait: float = 30.0,
              progress: Optional[Callable[[int, int], None]] = None) -> LiveResult:
    """Publish a recording's inputs to a running planner node with their recorded timing.

    Joins the ROS graph (``ROS_DOMAIN_ID`` and friends from the environment) with a node
    of its own, waits until the planner subscribes to every input topic the recording
    has, sets the recorded parameters (all but ``record``) atomically through the
    planner's parameter services, then publishes each recorded input, and applies each
    recorded parameter change, at its recorded time divided by `rate`. Messages go out
    as recorded, header stamps included, so the node's ``plan_info`` names them.
    Finally it waits for the node to answer the last input the recording shows answered.

    Parameters
    ----------
    bag : Bag
        The recording.
    rate : float
        Playback speed factor (2 = twice as fast).
    namespace : str, optional
        Namespace of the live node, if not the recorded one.
    set_parameters : bool
        Set the recorded parameters and changes on the node (else publish topics only).
    overrides : Mapping[str, object], optional
        Node parameters (``method``, ``w``, ...) to set instead of the recorded values.
    connect_timeout : float
        Longest wait for the node's subscriptions and parameter services [s].
    wait : float
        Longest wait for the answer to the last input after publishing [s].
    progress : callable, optional
        ``progress(done, total)`` after each input.

    Returns
    -------
    LiveResult
        Counts, the ``plan_info`` answers received and whether the last input was answered
        (None when the recording shows no answer to wait for).

    Raises
    ------
    ThreatPlannerError
        If no planner node subscribes in time, its parameter services do not answer, or it
        refuses the recorded parameters.

    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.signals import SignalHandlerOptions

    if not (math.isfinite(rate) and rate > 0.0):
        raise InputError(f'rate: must be finite and > 0, got {rate!r}')
    if not bag.inputs:
        raise RecordingError(f'{bag.path}: no inputs recorded: nothing to publish')
    overrides = {k: _declared(k, v) for k, v in (overrides or {}).items() if v is not None}
    ns = bag.namespace if namespace is None else _normalise_ns(namespace)
    node_name = _retarget(bag.node_name, bag.namespace, namespace)
    answered_keys = {(p.source, p.stamp_ns) for p in bag.plans}
    last_key = next(((_retarget(i.source, bag.namespace, namespace), i.stamp_ns)
                     for i in reversed(bag.inputs)
                     if i.source != _PARAMETERS and (i.source, i.stamp_ns) in answered_keys),
                    None)

    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = executor = thread = None
    try:
        node = rclpy.create_node(f'threat_planner_replay_{os.getpid()}', context=context,
                                 start_parameter_services=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        cond = threading.Condition()
        answers: List[Tuple[float, Dict[str, str]]] = []

        def on_info(msg) -> None:
            try:
                values = plan_info_values(msg)
            except InputError:
                return
            values['level'] = _level_name(msg.status[0].level)
            with cond:
                answers.append((time.monotonic(), values))
                cond.notify_all()

        from diagnostic_msgs.msg import DiagnosticArray
        node.create_subscription(DiagnosticArray, f'{ns}/plan_info', on_info, LATCHED)
        publishers = {}
        for inp in bag.inputs:
            if inp.source != _PARAMETERS and inp.source not in publishers:
                qos = INPUT_TOPICS[inp.kind][1]
                publishers[inp.source] = node.create_publisher(
                    type(inp.msg), _retarget(inp.source, bag.namespace, namespace), qos)

        def spin() -> None:
            try:
                executor.spin()
            except Exception:  # noqa: B902 - shutting the context down ends spin() so
                pass
        thread = threading.Thread(target=spin, daemon=True, name='replay-spin')
        thread.start()

        for pub in publishers.values():
            if not _wait(lambda pub=pub: pub.get_subscription_count() > 0, connect_timeout):
                raise ThreatPlannerError(
                    f'no subscriber on {pub.topic_name} within {connect_timeout:g} s: is the '
                    'planner node running, with the same ROS_DOMAIN_ID and namespace?')
        client = None
        if set_parameters:
            client = AsyncParameterClient(node, node_name)
            if not client.wait_for_services(timeout_sec=connect_timeout):
                raise ThreatPlannerError(
                    f'parameter services of {node_name} not available within '
                    f'{connect_timeout:g} s (--no-parameters publishes the topics only)')
            initial = [Parameter.from_parameter_msg(p) for p in bag.initial_parameter_msgs
                       if p.name != 'record' and p.name not in overrides]
            initial += [Parameter(k, value=v) for k, v in overrides.items()]
            if initial:
                _set_parameters(client, initial, node_name, connect_timeout)

        started = time.monotonic()
        t0 = bag.inputs[0].log_time_ns
        changes = 0
        for n, inp in enumerate(bag.inputs, 1):
            delay = started + 1e-9 * (inp.log_time_ns - t0) / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            if inp.source != _PARAMETERS:
                publishers[inp.source].publish(inp.msg)
            elif client is not None:
                params = [Parameter.from_parameter_msg(p) for p in inp.msg.changed_parameters
                          if p.name != 'record' and p.name not in overrides]
                if params:
                    _set_parameters(client, params, node_name, connect_timeout)
                    changes += 1
            if progress is not None:
                progress(n, len(bag.inputs))
        last_answered = None
        if last_key is not None:
            def answered() -> bool:
                with cond:
                    return any((a.get('input_source'), int(a.get('input_stamp_ns', -1)))
                               == last_key for _, a in answers)
            last_answered = _wait(answered, wait)
        duration = time.monotonic() - started
        ours = {(_retarget(i.source, bag.namespace, namespace), i.stamp_ns)
                for i in bag.inputs if i.source != _PARAMETERS}
        with cond:
            got = [a for t, a in answers
                   if (a.get('input_source'), int(a.get('input_stamp_ns', -1))) in ours
                   or (a.get('input_source') == _PARAMETERS and t >= started)]
        published = sum(inp.source != _PARAMETERS for inp in bag.inputs)
        return LiveResult(published, client is not None, changes, duration, got,
                          last_answered, ns, node_name)
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        if thread is not None:
            thread.join(5.0)


def _set_parameters(client, params, node_name: str, timeout: float) -> None:
    future = client.set_parameters_atomically(params)
    if not _wait(future.done, timeout):
        raise ThreatPlannerError(f'{node_name} did not answer a parameter change within '
                                 f'{timeout:g} s')
    result = future.result().result
    if not result.successful:
        names = ', '.join(p.name for p in params)
        raise ThreatPlannerError(f'{node_name} refused the recorded parameters ({names}): '
                                 f'{result.reason}')
