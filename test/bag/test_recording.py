"""Tests of the bag writer and reader: MCAP files in the ROS 2 profile, read back three ways."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_ros2._dynamic import generate_dynamic
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from sensor_msgs.msg import PointCloud2, PointField
import yaml

from threat_planner.bag import (INPUT_QOS, LATCHED_QOS, McapRecorder, message_definition,
                                msg_dependencies, read_messages, read_ros_messages, TopicQos)
from threat_planner.bag.definitions import _build_definition
from threat_planner.errors import RecordingError

REPO = Path(__file__).resolve().parents[2]
SEPARATOR = '=' * 80
T0 = 1_700_000_000_123_456_789  # ns; odd digits catch any float rounding of times

REQUIRED_TYPES = [
    'sensor_msgs/msg/PointCloud2', 'geometry_msgs/msg/PoseArray',
    'geometry_msgs/msg/PoseStamped', 'nav_msgs/msg/Path',
    'visualization_msgs/msg/MarkerArray', 'diagnostic_msgs/msg/DiagnosticArray',
    'rcl_interfaces/msg/ParameterEvent',
]


def make_path(n=4):
    msg = PathMsg()
    msg.header.frame_id = 'map'
    msg.header.stamp = Time(sec=1_700_000_000, nanosec=42)
    for i in range(n):
        pose = PoseStamped()
        pose.header.frame_id = 'map'
        pose.pose.position.x = 1.5 * i
        pose.pose.position.y = -2.0 * i
        pose.pose.position.z = 10.0 + i
        msg.poses.append(pose)
    return msg


def make_cloud():
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    msg = PointCloud2()
    msg.header.frame_id = 'world'
    msg.header.stamp = Time(sec=5, nanosec=6)
    msg.height, msg.width = 1, 4
    msg.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                  for k, n in enumerate('xyz')]
    msg.point_step, msg.row_step = 12, 48
    msg.data = points.tobytes()
    msg.is_dense = True
    return msg


def make_diagnostics():
    msg = DiagnosticArray()
    msg.header.stamp = Time(sec=7, nanosec=8)
    msg.status = [DiagnosticStatus(level=DiagnosticStatus.WARN, name='planner',
                                   message='slow', hardware_id='cpu0',
                                   values=[KeyValue(key='plan_ms', value='12.5')])]
    return msg


def write_sample(target, **kwargs):
    """Record one Path (latched), two clouds and one DiagnosticArray; return the recorder."""
    with McapRecorder(target, **kwargs) as rec:
        rec.add_topic('/planned_path', 'nav_msgs/msg/Path', LATCHED_QOS)
        rec.write('/planned_path', make_path(), log_time_ns=T0, publish_time_ns=T0 - 7)
        rec.write('/threats', make_cloud(), log_time_ns=T0 + 1)
        rec.write('/threats', make_cloud(), log_time_ns=T0 + 1_000_000_003,
                  publish_time_ns=T0 + 999)
        rec.write('/diagnostics', make_diagnostics(), log_time_ns=T0 + 2_000_000_000)
    return rec


def check_path(msg, n=4):
    assert msg.header.frame_id == 'map'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 42)
    assert len(msg.poses) == n
    for i, pose in enumerate(msg.poses):
        p = pose.pose.position
        assert (p.x, p.y, p.z) == (1.5 * i, -2.0 * i, 10.0 + i)
        assert pose.pose.orientation.w == 1.0


def check_cloud(msg):
    assert msg.header.frame_id == 'world'
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 4, 12, 48)
    assert [f.name for f in msg.fields] == ['x', 'y', 'z']
    assert [f.offset for f in msg.fields] == [0, 4, 8]
    assert all(f.datatype == PointField.FLOAT32 for f in msg.fields)
    points = np.frombuffer(bytes(msg.data), dtype=np.float32).reshape(4, 3)
    np.testing.assert_array_equal(points, np.arange(12, dtype=np.float32).reshape(4, 3))
    assert msg.is_dense


def check_diagnostics(msg):
    (status,) = msg.status
    assert (status.name, status.message, status.hardware_id) == ('planner', 'slow', 'cpu0')
    # 'byte' decodes as int (mcap_ros2, rosbags) or as a 1-byte bytes object (rclpy).
    level = status.level if isinstance(status.level, int) else status.level[0]
    assert level == 1
    assert [(kv.key, kv.value) for kv in status.values] == [('plan_ms', '12.5')]


EXPECTED_TIMES = [
    ('/planned_path', 'nav_msgs/msg/Path', T0, T0 - 7),
    ('/threats', 'sensor_msgs/msg/PointCloud2', T0 + 1, T0 + 1),
    ('/threats', 'sensor_msgs/msg/PointCloud2', T0 + 1_000_000_003, T0 + 999),
    ('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', T0 + 2_000_000_000,
     T0 + 2_000_000_000),
]


def check_sample(messages):
    assert [m[:4] for m in messages] == EXPECTED_TIMES
    check_path(messages[0].msg)
    check_cloud(messages[1].msg)
    check_cloud(messages[2].msg)
    check_diagnostics(messages[3].msg)


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


def test_definitions_follow_the_rosbag2_layout():
    share = Path(sys.prefix) / 'share'
    text = message_definition('nav_msgs/msg/Path')
    blocks = text.split(f'\n{SEPARATOR}\n')
    assert blocks[0] == (share / 'nav_msgs/msg/Path.msg').read_text()
    names = [b.split('\n', 1)[0] for b in blocks[1:]]
    # Depth first, dependencies of each level sorted, each type once.
    assert names == ['MSG: geometry_msgs/PoseStamped', 'MSG: geometry_msgs/Pose',
                     'MSG: geometry_msgs/Point', 'MSG: geometry_msgs/Quaternion',
                     'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert blocks[1] == 'MSG: geometry_msgs/PoseStamped\n' + \
        (share / 'geometry_msgs/msg/PoseStamped.msg').read_text()
    assert message_definition('nav_msgs/Path') == text


@pytest.mark.parametrize('type_name', REQUIRED_TYPES)
def test_required_types_have_definitions_both_parsers_accept(type_name):
    text = message_definition(type_name)
    assert type_name in generate_dynamic(type_name, text)
    types = get_types_from_msg(text, type_name)
    assert type_name in types
    if type_name == 'rcl_interfaces/msg/ParameterEvent':
        # Bare 'Parameter' resolves within rcl_interfaces.
        assert f'{SEPARATOR}\nMSG: rcl_interfaces/Parameter\n' in text


def test_msg_dependencies_parses_every_field_form():
    text = '\n'.join([
        '# comment with pkg/Fake type',
        'int32 CONSTANT=3  # a constant',
        'string<=10 BOUNDED_CONSTANT="a#b"',
        'Header header',
        'Local local',
        'Other[] unbounded',
        'Fixed[3] fixed',
        'Bounded[<=5] bounded',
        'geometry_msgs/Point point',
        'geometry_msgs/msg/Pose pose   # full form',
        'string<=8[<=2] names',
        'uint8[] data',
        '  float64 indented 0.5',
        '',
    ])
    assert msg_dependencies(text, 'my_pkg') == [
        'geometry_msgs/Point', 'geometry_msgs/Pose', 'my_pkg/Bounded', 'my_pkg/Fixed',
        'my_pkg/Local', 'my_pkg/Other', 'std_msgs/Header']


def test_definition_builder_recurses_and_emits_each_dependency_once():
    files = {
        'a/msg/Top': 'B[] bs\nb/C c\nstd_msgs/Header header\n',
        'a/msg/B': 'b/C c\nuint8 x\n',
        'b/msg/C': 'D d  # bare type in package b\n',
        'b/msg/D': 'float64 v\n',
        'std_msgs/msg/Header': 'string frame_id\n',
    }
    text = _build_definition('a/msg/Top', lambda name: files[name])
    assert text == (
        files['a/msg/Top']
        + f'\n{SEPARATOR}\nMSG: a/B\n' + files['a/msg/B']
        + f'\n{SEPARATOR}\nMSG: b/C\n' + files['b/msg/C']
        + f'\n{SEPARATOR}\nMSG: b/D\n' + files['b/msg/D']
        + f'\n{SEPARATOR}\nMSG: std_msgs/Header\n' + files['std_msgs/msg/Header'])


def test_unknown_type_is_a_recording_error(tmp_path):
    with pytest.raises(RecordingError, match='nosuch_msgs'):
        message_definition('nosuch_msgs/msg/Thing')
    with pytest.raises(RecordingError, match='not of the form'):
        message_definition('Path')
    with McapRecorder(tmp_path / 'x.mcap') as rec:
        with pytest.raises(RecordingError):
            rec.add_topic('/x', 'nosuch_msgs/msg/Thing')


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


# -- bad files -------------------------------------------------------------------------


def _multi_chunk_file(path, n=40):
    with McapRecorder(path, flush_interval_s=None) as rec:
        for i in range(n):
            rec.write('/planned_path', make_path(), log_time_ns=T0 + i)
            if i % 5 == 4:
                rec.flush()
    return n


def _assert_error_names_file(excinfo, path):
    text = str(excinfo.value)
    assert str(path) in text and '\n' not in text


def test_truncated_file_strict_raises_tolerant_reads_complete_chunks(tmp_path):
    out = tmp_path / 'cut.mcap'
    n = _multi_chunk_file(out)
    with open(out, 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[5]
    # Cut inside the sixth chunk, as a kill in the middle of writing it would.
    out.write_bytes(out.read_bytes()[:chunk.chunk_start_offset + chunk.chunk_length // 2])
    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(out))
    _assert_error_names_file(excinfo, out)
    with pytest.raises(RecordingError):
        list(read_ros_messages(out))
    got = list(read_messages(out, tolerant=True))
    assert len(got) == 25 < n  # the five complete chunks
    assert [m.log_time_ns for m in got] == [T0 + i for i in range(len(got))]
    for m in got:
        check_path(m.msg)
    assert len(list(read_ros_messages(out, tolerant=True))) == len(got)


def test_corrupt_chunk_raises(tmp_path):
    out = tmp_path / 'corrupt.mcap'
    _multi_chunk_file(out)
    with open(out, 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[1]
    data = bytearray(out.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 16] = bytes(b ^ 0xFF for b in data[middle:middle + 16])
    out.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match='corrupt') as excinfo:
        list(read_messages(out))
    _assert_error_names_file(excinfo, out)
    # The tolerant reader keeps the intact first chunk and stops at the damage.
    assert len(list(read_messages(out, tolerant=True))) == 5


@pytest.mark.parametrize('content', [b'', b'not an mcap file at all\n' * 20,
                                     b'\x89MCAP0\r\n'])
@pytest.mark.parametrize('tolerant', [False, True])
def test_non_mcap_file_raises(tmp_path, content, tolerant):
    out = tmp_path / 'junk.mcap'
    out.write_bytes(content)
    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(out, tolerant=tolerant))
    _assert_error_names_file(excinfo, out)


def test_missing_file_raises(tmp_path):
    with pytest.raises(RecordingError) as excinfo:
        list(read_messages(tmp_path / 'absent.mcap'))
    _assert_error_names_file(excinfo, tmp_path / 'absent.mcap')


@pytest.mark.parametrize('tolerant', [False, True])
def test_unknown_schema_encoding_raises(tmp_path, tolerant):
    out = tmp_path / 'proto.mcap'
    with open(out, 'wb') as f:
        writer = Writer(f)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('foo_msgs/msg/Bar', 'protobuf', b'\x0a\x03Bar')
        channel = writer.register_channel('/bar', 'cdr', schema)
        writer.add_message(channel, log_time=1, data=b'\x00\x01\x00\x00', publish_time=1)
        writer.finish()
    with pytest.raises(RecordingError, match='protobuf') as excinfo:
        list(read_messages(out, tolerant=tolerant))
    _assert_error_names_file(excinfo, out)


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


def test_mcap_can_end_a_chunk():
    """The crash-safety flush needs mcap's Writer.flush or its private __finalize_chunk.

    If a new mcap release drops both, this fails loudly instead of recordings silently
    losing their last second on a crash (see threat_planner.bag.writer.end_chunk).
    """
    from mcap.writer import Writer
    assert callable(getattr(Writer, 'flush', None)) or \
        callable(getattr(Writer, '_Writer__finalize_chunk', None))
