"""MCAP recordings of the planner node: writing, reading, repairing.

Files are what ``ros2 bag record -s mcap`` (rosbag2, Jazzy) writes: header profile
``ros2``, one ``ros2msg`` schema per message type holding the full concatenated ``.msg``
text, ``cdr`` channels carrying ``offered_qos_profiles``, zstd-compressed chunks. Modules:
:mod:`.qos` (offered QoS), :mod:`.definitions` (message types and definitions),
:mod:`.writer` (:class:`McapRecorder`), :mod:`.reader` (strict and tolerant reading),
:mod:`.cdr` (CDR encoding), :mod:`.metadata` (rosbag2's ``metadata.yaml``), :mod:`.repair`
(salvage a cut bag). Storage only: it imports nothing of the ROS edge; the tools that run
it (record, replay, live) are in :mod:`threat_planner.ros.recording`.

The names below load on first use (PEP 562): a plan process that needs only :mod:`.cdr`
does not pay for mcap and the message definitions (65 ms of a node's start-up).
"""

import importlib

_HOMES = {
    'deserialize': 'definitions', 'get_message_class': 'definitions',
    'message_definition': 'definitions', 'message_type_name': 'definitions',
    'msg_dependencies': 'definitions', 'INPUT_QOS': 'qos', 'LATCHED_QOS': 'qos',
    'TopicQos': 'qos', 'read_messages': 'reader', 'read_ros_messages': 'reader',
    'RecordedMessage': 'reader', 'recorded_topics': 'reader', 'McapRecorder': 'writer',
}

__all__ = ['INPUT_QOS', 'LATCHED_QOS', 'McapRecorder', 'RecordedMessage', 'TopicQos',
           'deserialize', 'get_message_class', 'message_definition', 'message_type_name',
           'msg_dependencies', 'read_messages', 'read_ros_messages', 'recorded_topics']


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'{__name__}.{home}'), name)
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(__all__))
