"""Tests of the bag writer and reader: MCAP files in the ROS 2 profile, read back three ways."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
from nav_msgs.msg import Path as PathMsg
import pytest
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from sensor_msgs.msg import PointCloud2
import yaml

from bag_samples import (check_cloud, check_diagnostics, check_path, check_sample,
                         EXPECTED_TIMES, make_cloud, make_diagnostics, make_path, SEPARATOR, T0,
                         write_sample)
from threat_planner.bag import (INPUT_QOS, LATCHED_QOS, McapRecorder, message_definition,
                                read_messages, read_ros_messages, TopicQos)
from threat_planner.errors import RecordingError

REPO = Path(__file__).resolve().parents[2]


# -- round trip ------------------------------------------------------------------------


def test_round_trip_with_mcap_ros2_decoder(tmp_path):
    out = tmp_path / 'run.mcap'
    rec = write_sample(out)
    assert rec.path == out and rec.bag_dir is None and rec.message_count == 4
    check_sample(list(read_messages(out)))
    # The tolerant reader gives the same on a complete file.
    check_sample(list(read_messages(out, tolerant=True)))
    assert [m.topic for m in read_messages(out, topics=['/threats'])] == ['/threats'] * 2


def test_round_trip_to_rclpy_classes(tmp_path):
    out = tmp_path / 'run.mcap'
    write_sample(out)
    messages = list(read_ros_messages(out))
    assert [m[:4] for m in messages] == EXPECTED_TIMES
    assert isinstance(messages[0].msg, PathMsg) and messages[0].msg == make_path()
    assert isinstance(messages[1].msg, PointCloud2) and messages[1].msg == make_cloud()
    assert messages[3].msg == make_diagnostics()


def test_already_serialised_bytes_are_recorded_verbatim(tmp_path):
    from rclpy.serialization import serialize_message
    out = tmp_path / 'raw.mcap'
    raw = serialize_message(make_path(2))
    with McapRecorder(out) as rec:
        with pytest.raises(RecordingError, match='type_name'):
            rec.write('/p', raw, log_time_ns=1)
        rec.write('/p', raw, 'nav_msgs/Path', log_time_ns=5)
    with open(out, 'rb') as f:
        (_, _, message), = make_reader(f).iter_messages()
    assert message.data == raw
    check_path(next(read_messages(out)).msg, n=2)


# -- file format -----------------------------------------------------------------------


def test_file_is_ros2_profile_with_full_schemas_qos_and_zstd_chunks(tmp_path):
    out = tmp_path / 'run.mcap'
    write_sample(out)
    with open(out, 'rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == 'ros2'
    assert 'threat_planner' in header.library
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == {'nav_msgs/msg/Path', 'sensor_msgs/msg/PointCloud2',
                            'diagnostic_msgs/msg/DiagnosticArray'}
    for name, schema in schemas.items():
        assert schema.encoding == 'ros2msg'
        text = schema.data.decode()
        assert text == message_definition(name)
        assert f'\n{SEPARATOR}\nMSG: std_msgs/Header\n' in text
        assert f'\n{SEPARATOR}\nMSG: builtin_interfaces/Time\n' in text
    assert f'{SEPARATOR}\nMSG: sensor_msgs/PointField\n' in \
        schemas['sensor_msgs/msg/PointCloud2'].data.decode()
    channels = {c.topic: c for c in summary.channels.values()}
    for topic, channel in channels.items():
        assert channel.message_encoding == 'cdr'
        (qos,) = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        assert qos['reliability'] == 'reliable'
        assert qos['durability'] == ('transient_local' if topic == '/planned_path'
                                     else 'volatile')
        assert qos['history'] == 'keep_last'
        assert qos['depth'] == (1 if topic == '/planned_path' else 10)
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
    assert summary.chunk_indexes
    assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
    assert summary.statistics.message_count == 4


# -- folder form, metadata.yaml and rosbags ----------------------------------------------


def test_folder_recording_has_rosbag2_metadata(tmp_path):
    rec = write_sample(tmp_path / 'bags')
    bag = rec.bag_dir
    assert bag.parent == tmp_path / 'bags' and bag.name.startswith('threat_planner_')
    assert rec.path == bag / f'{bag.name}_0.mcap' and rec.path.is_file()
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == [rec.path.name]
    assert info['message_count'] == 4
    assert info['starting_time'] == {'nanoseconds_since_epoch': T0}
    assert info['duration'] == {'nanoseconds': 2_000_000_000}
    assert info['compression_format'] == '' and info['compression_mode'] == ''
    assert info['files'] == [{'path': rec.path.name,
                              'starting_time': {'nanoseconds_since_epoch': T0},
                              'duration': {'nanoseconds': 2_000_000_000},
                              'message_count': 4}]
    assert 'custom_data' in info and info['ros_distro']
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert {k: v['message_count'] for k, v in topics.items()} == {
        '/planned_path': 1, '/threats': 2, '/diagnostics': 1}
    meta = topics['/planned_path']['topic_metadata']
    assert meta['type'] == 'nav_msgs/msg/Path' and meta['serialization_format'] == 'cdr'
    assert meta['type_description_hash'].startswith('RIHS01_')
    (qos,) = meta['offered_qos_profiles']
    assert (qos['reliability'], qos['durability'], qos['history'], qos['depth']) == (
        'reliable', 'transient_local', 'keep_last', 1)
    # A bag directory reads like its file.
    check_sample(list(read_messages(bag)))
    # A folder given without .mcap suffix that does not exist yet is created.
    rec2 = write_sample(tmp_path / 'new' / 'runs')
    assert rec2.bag_dir.parent == tmp_path / 'new' / 'runs'


def test_two_recorders_in_one_second_get_separate_bags(tmp_path):
    with McapRecorder(tmp_path, prefix='p') as a, McapRecorder(tmp_path, prefix='p') as b:
        assert a.bag_dir != b.bag_dir


def _rosbags_messages(reader):
    """Deserialise with a typestore built only from the definitions in the file."""
    store = get_typestore(Stores.EMPTY)
    for conn in reader.connections:
        store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
    return [(conn.topic, conn.msgtype, stamp, store.deserialize_cdr(raw, conn.msgtype))
            for conn, stamp, raw in reader.messages()]


def test_rosbags_reads_the_bag_directory_and_the_file(tmp_path):
    rec = write_sample(tmp_path)
    for target in (rec.bag_dir, rec.path):
        with RosbagsReader(target) as reader:
            assert reader.message_count == 4
            qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
            assert qos['/planned_path'].durability == QosDurability.TRANSIENT_LOCAL
            assert qos['/threats'].durability == QosDurability.VOLATILE
            messages = sorted(_rosbags_messages(reader), key=lambda m: m[2])
        assert [m[:3] for m in messages] == [e[:3] for e in EXPECTED_TIMES]
        check_path(messages[0][3])
        check_cloud(messages[1][3])
        check_diagnostics(messages[3][3])


# -- robustness ------------------------------------------------------------------------


def test_exception_inside_with_still_finishes_the_file(tmp_path):
    out = tmp_path / 'boom.mcap'
    with pytest.raises(ZeroDivisionError):
        with McapRecorder(out) as rec:
            rec.write('/planned_path', make_path(), log_time_ns=T0)
            1 / 0
    assert rec.closed
    assert [m.log_time_ns for m in read_messages(out)] == [T0]
    with pytest.raises(RecordingError, match='closed'):
        rec.write('/planned_path', make_path(), log_time_ns=T0)
    rec.close()  # idempotent


def test_bad_writes_are_recording_errors(tmp_path):
    with McapRecorder(tmp_path / 'x.mcap') as rec:
        rec.write('/planned_path', make_path(), log_time_ns=1)
        with pytest.raises(RecordingError, match='/planned_path'):
            rec.write('/planned_path', make_cloud(), log_time_ns=2)
        with pytest.raises(RecordingError, match='not the given'):
            rec.write('/other', make_path(), 'sensor_msgs/msg/PointCloud2', log_time_ns=2)
        with pytest.raises(RecordingError, match='log_time_ns'):
            rec.write('/planned_path', make_path(), log_time_ns=-1)
        with pytest.raises(RecordingError, match='not a generated ROS 2 message'):
            rec.write('/planned_path', {'x': 1}, log_time_ns=3)
    with pytest.raises(RecordingError, match='durability'):
        TopicQos(durability='sticky')
    assert INPUT_QOS.durability == 'volatile' and LATCHED_QOS.depth == 1


def test_time_based_flush_puts_messages_on_disk_while_recording(tmp_path):
    out = tmp_path / 'live.mcap'
    with McapRecorder(out, flush_interval_s=0.2) as rec:
        rec.write('/planned_path', make_path(), log_time_ns=T0)
        deadline = time.monotonic() + 3.0
        seen = []
        while not seen and time.monotonic() < deadline:
            time.sleep(0.05)
            seen = list(read_messages(out, tolerant=True))
        assert [m.log_time_ns for m in seen] == [T0]
        with pytest.raises(RecordingError, match='truncated'):
            list(read_messages(out))


KILLED_WRITER = r"""
import os, signal, sys, time
from geometry_msgs.msg import PoseStamped
from threat_planner.bag import McapRecorder

rec = McapRecorder(sys.argv[1], prefix='killed')   # default chunk size and 1 s flush
end = time.monotonic() + 2.5
i = 0
while time.monotonic() < end:
    msg = PoseStamped()
    msg.header.frame_id = 'map'
    msg.pose.position.x = float(i)
    rec.write('/pose', msg, log_time_ns=time.time_ns())
    i += 1
    time.sleep(0.004)
print(i, time.time_ns(), flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_sigkill_loses_at_most_the_last_second(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    proc = subprocess.run([sys.executable, '-c', KILLED_WRITER, str(tmp_path)], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    written, killed_ns = map(int, proc.stdout.split())
    (bag,) = tmp_path.iterdir()
    (mcap_file,) = bag.glob('*.mcap')

    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(mcap_file))
    assert str(mcap_file) in str(excinfo.value) and '\n' not in str(excinfo.value)

    got = list(read_messages(bag, tolerant=True))
    # A gap-free prefix of what was written, decoded without error...
    assert [m.msg.pose.position.x for m in got] == [float(i) for i in range(len(got))]
    assert 0 < len(got) <= written
    # ...reaching to within ~1 s (flush interval plus scheduling slack) of the kill.
    assert got[-1].log_time_ns >= killed_ns - 1_200_000_000
    # The metadata.yaml refreshed at each flush never claims more than the file holds.
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert 0 < info['message_count'] <= len(got)


def test_rclpy_qos_profiles_are_accepted(tmp_path):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    assert TopicQos.from_rclpy(latched) == LATCHED_QOS
    out = tmp_path / 'qos.mcap'
    with McapRecorder(out) as rec:
        rec.write('/planned_path', make_path(), log_time_ns=1, qos=latched)
    with open(out, 'rb') as f:
        (channel,) = make_reader(f).get_summary().channels.values()
    assert yaml.safe_load(channel.metadata['offered_qos_profiles']) == [LATCHED_QOS.as_dict()]


def test_the_crash_safety_flush_uses_mcap_s_public_api_only():
    """mcap >= 1.6's Writer.flush ends the chunk in progress; no private name of mcap is used.

    setup.py's 'record' extra asks for that floor; the fallback to the private
    ``__finalize_chunk`` that older releases needed is gone.
    """
    import importlib.metadata
    from mcap.writer import Writer
    major, minor = map(int, importlib.metadata.version('mcap').split('.')[:2])
    assert (major, minor) >= (1, 6) and callable(getattr(Writer, 'flush', None))
    private = [str(f.relative_to(REPO)) for f in (REPO / 'threat_planner').rglob('*.py')
               if '_Writer__' in f.read_text()]
    assert private == []
