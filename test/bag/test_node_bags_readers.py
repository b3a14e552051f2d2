"""Bags in test/data/bags (the live node's, and flights) open in every common reader.

rosbags' AnyReader with the bag's own definitions and with its Jazzy typestore,
mcap_ros2's decoder and rclpy all decode every message; the payload is exact CDR (what
rosbags' own serialiser writes back, byte for byte, so no trailing or uninitialised bytes).
"""

from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores

from threat_planner.bag import deserialize

BAGS = sorted((Path(__file__).resolve().parents[1] / 'data' / 'bags').glob('*.mcap'))
JAZZY = get_typestore(Stores.ROS2_JAZZY)


@pytest.mark.parametrize('bag', BAGS, ids=lambda p: p.stem)
def test_every_topic_decodes_in_every_reader(bag):
    seen: dict[str, int] = {}
    with AnyReader([bag]) as reader:   # the bag's own definitions
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            msg = JAZZY.deserialize_cdr(raw, connection.msgtype)
            assert JAZZY.serialize_cdr(msg, connection.msgtype) == raw, connection.topic
            deserialize(raw, connection.msgtype)   # rclpy
            seen[connection.topic] = seen.get(connection.topic, 0) + 1
    with open(bag, 'rb') as f:
        decoded = sum(1 for _ in make_reader(f, decoder_factories=[DecoderFactory()])
                      .iter_decoded_messages())
    assert decoded == sum(seen.values())
    # A flight (threat-planner fly --record) has the vehicle and its events instead of
    # the network a node plan draws.
    flight = any(t.endswith('/flight_setup') for t in seen)
    wanted = ('/odom', '/events', '/flight_setup', '/flight_result') if flight else (
        '/initial_path', '/network')
    for topic in ('/parameter_events', '/threats', '/path', '/plan_info') + wanted:
        assert any(t.endswith(topic) for t in seen), (topic, sorted(seen))
