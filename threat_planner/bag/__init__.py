"""MCAP recordings of the planner node: writing, reading, repairing.

Files are what ``ros2 bag record -s mcap`` (rosbag2, Jazzy) writes: header profile
``ros2``, one ``ros2msg`` schema per message type holding the full concatenated ``.msg``
text, ``cdr`` channels carrying ``offered_qos_profiles``, zstd-compressed chunks. Modules:
:mod:`.qos` (offered QoS), :mod:`.definitions` (message types and definitions),
:mod:`.writer` (:class:`McapRecorder`), :mod:`.reader` (strict and tolerant reading),
:mod:`.cdr` (CDR encoding), :mod:`.metadata` (rosbag2's ``metadata.yaml``), :mod:`.repair`
(salvage a cut bag). Storage only: it imports nothing of the ROS edge; the tools that run
it (record, replay, live) are in :mod:`threat_planner.ros.recording`.
"""

from threat_planner.bag.definitions import (deserialize, get_message_class, message_definition,
                                            message_type_name, msg_dependencies)
from threat_planner.bag.qos import INPUT_QOS, LATCHED_QOS, TopicQos
from threat_planner.bag.reader import (read_messages, read_ros_messages, RecordedMessage,
                                       recorded_topics)
from threat_planner.bag.writer import McapRecorder

__all__ = ['INPUT_QOS', 'LATCHED_QOS', 'McapRecorder', 'RecordedMessage', 'TopicQos',
           'deserialize', 'get_message_class', 'message_definition', 'message_type_name',
           'msg_dependencies', 'read_messages', 'read_ros_messages', 'recorded_topics']
