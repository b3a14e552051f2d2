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

from threat_planner._lazy import lazy_names

__all__ = ['INPUT_QOS', 'LATCHED_QOS', 'McapRecorder', 'RecordedMessage', 'TopicQos',
           'deserialize', 'get_message_class', 'message_definition', 'message_type_name',
           'msg_dependencies', 'read_messages', 'read_ros_messages', 'recorded_topics']

__getattr__, __dir__ = lazy_names(__name__, {
    **dict.fromkeys(('deserialize', 'get_message_class', 'message_definition',
                     'message_type_name', 'msg_dependencies'), f'{__name__}.definitions'),
    **dict.fromkeys(('INPUT_QOS', 'LATCHED_QOS', 'TopicQos'), f'{__name__}.qos'),
    **dict.fromkeys(('read_messages', 'read_ros_messages', 'RecordedMessage',
                     'recorded_topics'), f'{__name__}.reader'),
    'McapRecorder': f'{__name__}.writer'}, __all__)
