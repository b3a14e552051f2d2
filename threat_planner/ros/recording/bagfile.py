"""A planner node's recording read for replay: parameters, inputs and plan outputs."""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence

from numpy.typing import NDArray

from threat_planner.bag.reader import read_ros_messages, RecordedMessage, recorded_topics
from threat_planner.errors import InputError, RecordingError
from threat_planner.ros.conversions import (path_from_msg, PLAN_STATUS_NAME, plan_info_values,
                                            stamp_to_ns)
from threat_planner.ros.inputs import input_stamp
from threat_planner.ros.interface import (INPUT_TOPICS, NODE_NAME, OUTPUT_TOPICS,
                                          PARAMETER_EVENT_TYPE, PARAMETER_EVENTS_TOPIC)
from threat_planner.ros.parameters import PARAMETER_DEFAULTS

__all__ = ['Bag', 'BagInput', 'BagPlan', 'PARAMETERS', 'level_name', 'load_bag',
           'parameter_values']

_THREAT_TOPICS = ('threats', 'threat_poses')
#: ``input_source`` and ``kind`` of a parameter change.
PARAMETERS = 'parameters'
_LEVEL_NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}


def level_name(level) -> str:
    """Name a DiagnosticStatus level (rclpy gives the ``byte`` as a 1-byte bytes object)."""
    if isinstance(level, (bytes, bytearray)):
        level = level[0] if level else -1
    return _LEVEL_NAMES.get(int(level), str(level))


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
    def path_stamp_ns(self) -> int:
        """Header stamp of the paths published for it [ns]: ``t0_ns``, the trajectory's t0.

        A recording made before the paths were trajectories has no ``t0_ns``; its paths
        carry the input's stamp.
        """
        return int(self.values.get('t0_ns', self.stamp_ns))

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


def parameter_values(params) -> Dict[str, object]:
    """Python values of ``rcl_interfaces/msg/Parameter`` messages, by name."""
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
            PARAMETER_EVENT_TYPE:
        raise RecordingError(f'{path}: {PARAMETER_EVENTS_TOPIC} is a '
                             f'{topics[PARAMETER_EVENTS_TOPIC]}, not a {PARAMETER_EVENT_TYPE}')
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
                parameters.update(parameter_values(event.new_parameters))
                initial_msgs = list(event.new_parameters)
            elif event.node == node_name and event.changed_parameters:
                inputs.append(BagInput(len(inputs) + 1, PARAMETERS, PARAMETERS,
                                       m.log_time_ns, stamp_to_ns(event.stamp), event))
        elif m.topic in kinds:
            inputs.append(BagInput(len(inputs) + 1, m.topic, kinds[m.topic], m.log_time_ns,
                                   stamp_to_ns(input_stamp(m.msg)), m.msg))
    plans = []
    for m in by_topic.get(f'{ns}/plan_info', []):
        try:
            values = plan_info_values(m.msg)
        except InputError:
            continue  # some other node's diagnostics
        status = next(d for d in m.msg.status if d.name == PLAN_STATUS_NAME)
        plan_ = BagPlan(len(plans) + 1, m.log_time_ns, level_name(status.level),
                        status.message, values)
        if plan_.level != 'ERROR':
            plan_.initial_path = _points_before(by_topic.get(f'{ns}/initial_path', []),
                                                plan_.path_stamp_ns, m.log_time_ns)
            plan_.path = _points_before(by_topic.get(f'{ns}/path', []), plan_.path_stamp_ns,
                                        m.log_time_ns)
        plans.append(plan_)
    return Bag(path, ns, node_name, parameters, recorded_params, inputs, plans, initial_msgs)
