"""Tests of threat_planner.bag.cdr: recorded CDR payloads that every reader decodes.

The claims: the recorder's payloads equal, byte for byte, what two independent encoders
(mcap_ros2's CdrWriter and rosbags' serializer, both zero-padding and exact-length) make
of the same message; they decode with rclpy, mcap_ros2 and rosbags (its own Jazzy
typestore and the definitions stored in the file) to equal messages; and encoding one
message twice gives identical bytes although rclpy leaves its padding uninitialised.
"""

import array
import dataclasses
import gc
from pathlib import Path
import subprocess
import sys

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped
from hypothesis import given, HealthCheck, settings, strategies as st
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterType, ParameterValue
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, get_types_from_msg, Stores
from sensor_msgs.msg import CameraInfo, PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray, UVCoordinate

from threat_planner.bag import McapRecorder, message_definition, message_type_name
from threat_planner.bag.cdr import CdrLayout, canonical_cdr, parse_definition
from threat_planner.errors import RecordingError

REPO = Path(__file__).resolve().parents[2]
JAZZY = get_typestore(Stores.ROS2_JAZZY)


def header(frame):
    return Header(frame_id=frame, stamp=Time(sec=1_700_000_001, nanosec=987_654_321))


def make_cloud():
    fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
              for k, n in enumerate(['x', 'yy', 'zzz', 'intensity'])]
    return PointCloud2(header=header('map'), height=1, width=3, fields=fields,
                       is_bigendian=False, point_step=16, row_step=48,
                       data=bytes(range(1, 14)), is_dense=True)  # 13 bytes: odd


def make_pose_array(n=3):
    poses = [Pose() for _ in range(n)]
    for i, p in enumerate(poses):
        p.position = Point(x=1.0 + i, y=-2.5 * i, z=1e-3)
        p.orientation.w = 0.5
    return PoseArray(header=header('world'), poses=poses)


def make_pose_stamped(frame='a'):
    msg = PoseStamped(header=header(frame))
    msg.pose.position = Point(x=3.0, y=4.0, z=5.0)
    return msg


def make_path():
    return PathMsg(header=header('map'),
                   poses=[make_pose_stamped('f' * k) for k in range(5)])


def make_markers():
    empty = Marker(header=header(''), ns='', id=0)
    full = Marker(header=header('map7'), ns='net', id=-3, type=Marker.LINE_LIST,
                  action=Marker.ADD, frame_locked=True, text='odd',
                  lifetime=Duration(sec=2, nanosec=5), mesh_resource='package://x/y.dae',
                  texture_resource='t', mesh_use_embedded_materials=True)
    full.scale.x = 0.25
    full.color = ColorRGBA(r=0.125, g=0.25, b=0.375, a=1.0)  # float32-exact
    full.points = [Point(x=float(i), y=2.0 * i, z=-1.0) for i in range(7)]
    full.colors = [ColorRGBA(r=1.0, a=0.5)] * 7
    full.uv_coordinates = [UVCoordinate(u=0.5, v=0.25)] * 3
    full.texture.format = 'png'
    full.texture.data = bytes([7, 8, 9])
    full.mesh_file.filename = 'm.stl'
    full.mesh_file.data = array.array('B', [1, 2, 3, 4, 5])
    return MarkerArray(markers=[empty, full, Marker(ns='ab', text='')])


def make_diagnostics():
    status = [DiagnosticStatus(level=DiagnosticStatus.WARN, name='planner', message='slow',
                               hardware_id='cpu0',
                               values=[KeyValue(key='J', value='1.5'),
                                       KeyValue(key='seq', value='')]),
              DiagnosticStatus(level=DiagnosticStatus.OK, name='x')]
    return DiagnosticArray(header=header('map'), status=status)


def make_parameter_event():
    def param(name, **value):
        return Parameter(name=name, value=ParameterValue(**value))

    new = [param('w', type=ParameterType.PARAMETER_DOUBLE, double_value=0.5),
           param('method', type=ParameterType.PARAMETER_STRING, string_value='best'),
           param('k', type=ParameterType.PARAMETER_INTEGER, integer_value=-7),
           param('on', type=ParameterType.PARAMETER_BOOL, bool_value=True),
           param('raw', type=ParameterType.PARAMETER_BYTE_ARRAY,
                 byte_array_value=[b'\x01', b'\x7f', b'\x03']),
           param('flags', type=ParameterType.PARAMETER_BOOL_ARRAY,
                 bool_array_value=[True, False, True]),
           param('ids', type=ParameterType.PARAMETER_INTEGER_ARRAY,
                 integer_array_value=[1, -2, 3]),
           param('bounds', type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                 double_array_value=[0.0, 100.0, 1e-300]),
           param('names', type=ParameterType.PARAMETER_STRING_ARRAY,
                 string_array_value=['a', 'bcd', ''])]
    return ParameterEvent(stamp=Time(sec=3, nanosec=4), node='/threat_planner',
                          new_parameters=new, changed_parameters=new[:1],
                          deleted_parameters=[])


def make_camera_info():
    # Fixed arrays (float64[9], [12]), a float64 sequence and a nested fixed struct.
    msg = CameraInfo(header=header('cam'), height=480, width=640,
                     distortion_model='plumb_bob', d=[0.1, -0.2, 0.0], binning_x=1)
    msg.k = [float(i) for i in range(9)]
    msg.p = [float(-i) for i in range(12)]
    msg.roi.do_rectify = True
    return msg


MESSAGES = {
    'PointCloud2': make_cloud, 'PoseArray': make_pose_array,
    'PoseArray (empty)': lambda: make_pose_array(0), 'PoseStamped': make_pose_stamped,
    'Path': make_path, 'Path (empty)': lambda: PathMsg(header=header('xyz')),
    'MarkerArray': make_markers, 'MarkerArray (empty)': MarkerArray,
    'DiagnosticArray': make_diagnostics, 'ParameterEvent': make_parameter_event,
    'ParameterEvent (empty)': ParameterEvent, 'CameraInfo': make_camera_info,
}


def plain(value, ros_type=None):
    """Turn a message of any of the three libraries into nested dicts, lists and numbers."""
    if hasattr(value, 'get_fields_and_field_types'):  # rclpy
        return {name: plain(getattr(value, name), t)
                for name, t in value.get_fields_and_field_types().items()}
    if dataclasses.is_dataclass(value):  # rosbags: constants are the fields with defaults
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.default is dataclasses.MISSING}
    if hasattr(value, '__slots__') and not isinstance(value, (str, bytes)):  # mcap_ros2
        return {name: plain(getattr(value, name)) for name in value.__slots__}
    if ros_type == 'octet' and isinstance(value, bytes):
        return value[0]  # rclpy's byte is a 1-byte bytes object; the others give int
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple, bytes, bytearray, array.array)):
        inner = ros_type[9:-1] if ros_type and ros_type.startswith('sequence<') else None
        if inner is None and ros_type and '[' in ros_type:
            inner = ros_type.split('[')[0]
        return [plain(v, inner) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def decoders(type_name):
    """The four decoders of the claim, by name."""
    definition = message_definition(type_name)
    own = get_typestore(Stores.EMPTY)
    own.register(get_types_from_msg(definition, type_name))
    mcap_decode = generate_dynamic(type_name, definition)[type_name]
    cls = type(MESSAGES_BY_TYPE[type_name]())
    return {'rclpy': lambda b: deserialize_message(b, cls),
            'mcap_ros2': mcap_decode,
            'rosbags (Jazzy typestore)': lambda b: JAZZY.deserialize_cdr(b, type_name),
            'rosbags (bag definitions)': lambda b: own.deserialize_cdr(b, type_name)}


MESSAGES_BY_TYPE = {message_type_name(make()): make for make in MESSAGES.values()}


def recorded_bytes(msg):
    """Serialise as McapRecorder does."""
    return McapRecorder._serialize('/t', msg)


@pytest.mark.parametrize('label', MESSAGES)
def test_payload_equals_two_independent_zero_padded_encoders(label):
    msg = MESSAGES[label]()
    type_name = message_type_name(msg)
    data = recorded_bytes(msg)
    encode = serialize_dynamic(type_name, message_definition(type_name))[type_name]
    assert data == bytes(encode(plain(msg)))
    assert data == bytes(JAZZY.serialize_cdr(JAZZY.deserialize_cdr(data, type_name),
                                             type_name))


@pytest.mark.parametrize('label', MESSAGES)
def test_every_reader_decodes_the_payload_to_the_same_message(label):
    msg = MESSAGES[label]()
    data = recorded_bytes(msg)
    expected = plain(msg)
    for name, decode in decoders(message_type_name(msg)).items():
        assert plain(decode(data)) == expected, name


@pytest.mark.parametrize('label', MESSAGES)
def test_two_encodings_are_identical_and_extra_bytes_are_cut(label):
    msg = MESSAGES[label]()
    first = recorded_bytes(msg)
    # Churn the heap so that rclpy's uninitialised padding would differ.
    junk = [serialize_message(make_parameter_event()) for _ in range(50)]
    del junk
    gc.collect()
    assert recorded_bytes(msg) == first
    raw = serialize_message(msg)
    layout = CdrLayout(message_type_name(msg), message_definition(message_type_name(msg)))
    assert layout.extent(raw)[0] == len(first) <= len(raw)
    # Junk after the payload is not part of it.
    assert layout.canonical(raw + b'\xaa' * 11) == first


text = st.text(st.characters(codec='utf-8', exclude_characters='\x00'), max_size=9)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames=st.lists(text, max_size=4), keys=st.lists(st.tuples(text, text), max_size=4),
       level=st.integers(0, 3), xs=st.lists(st.floats(allow_nan=False), max_size=5))
def test_random_messages_match_mcap_ros2_and_round_trip(frames, keys, level, xs):
    path = PathMsg(header=header(frames[0] if frames else ''),
                   poses=[make_pose_stamped(f) for f in frames])
    for pose, x in zip(path.poses, xs):
        pose.pose.position.x = x
    diag = DiagnosticArray(header=header('m'), status=[DiagnosticStatus(
        level=bytes([level]), name=k, values=[KeyValue(key=k, value=v) for k, v in keys])
        for k, _ in keys])
    for msg in (path, diag):
        type_name = message_type_name(msg)
        data = recorded_bytes(msg)
        encode = serialize_dynamic(type_name, message_definition(type_name))[type_name]
        assert data == bytes(encode(plain(msg)))
        assert deserialize_message(data, type(msg)) == msg
        assert plain(JAZZY.deserialize_cdr(data, type_name)) == plain(msg)


# -- the walk itself, on definitions no installed message has ----------------------------

ODD = 'uint8 a\nfloat64 b\nuint16 c\n'
HOLDER = ('Odd[] items\nuint8 tail\nOdd[2] pair\nint32 N=5  # constant\n'
          'string<=4 short "ab"\nint16[<=3] few\n'
          f'{"=" * 80}\nMSG: pkg/Odd\n{ODD}')


def test_parse_definition_skips_constants_and_reads_every_array_form():
    types = parse_definition(HOLDER, 'pkg/Holder')
    assert [(f.name, f.base, f.count) for f in types['pkg/msg/Holder']] == [
        ('items', 'pkg/msg/Odd', -1), ('tail', 'uint8', None), ('pair', 'pkg/msg/Odd', 2),
        ('short', 'string', None), ('few', 'int16', -1)]
    assert [f.name for f in types['pkg/msg/Odd']] == ['a', 'b', 'c']
    # An empty message gets rosidl's placeholder member.
    assert [f.name for f in parse_definition('# nothing\n', 'std_msgs/Empty')[
        'std_msgs/msg/Empty']] == ['structure_needs_at_least_one_member']


def insensitive_bytes(data, decode):
    """Brute force: positions whose value the decoder ignores (set to 0 or 1 and decode)."""
    reference = plain(decode(data))
    out = []
    for i in range(4, len(data)):
        probe = bytearray(data)
        probe[i] = 0 if data[i] else 1
        try:
            same = plain(decode(bytes(probe))) == reference
        except Exception:  # noqa: B902 - a changed length byte may make it undecodable
            same = False
        if same:
            out.append(i)
    return out


@pytest.mark.parametrize('n_items', [0, 1, 2, 5])
def test_padding_found_by_the_walk_is_exactly_what_decoders_ignore(n_items):
    # Odd's layout depends on its start offset mod 8, so runs of it exercise every path.
    name = 'pkg/msg/Holder'
    odd = {'a': 1, 'b': 2.5, 'c': 3}
    value = {'items': [dict(odd, a=i + 1) for i in range(n_items)], 'tail': 9,
             'pair': [odd, odd], 'short': 'abc', 'few': [1, 2, 3][:n_items % 4]}
    data = bytes(serialize_dynamic(name, HOLDER)[name](value))
    decode = generate_dynamic(name, HOLDER)[name]
    ignored = insensitive_bytes(data, decode)
    end, pads, runs = CdrLayout(name, HOLDER).extent(data)
    found = {i for a, b in pads for i in range(a, b)}
    found |= {start + k * size + i for start, size, count, rel in runs
              for k in range(count) for a, b in rel for i in range(a, b)}
    assert end == len(data)
    # The string's NUL is ignored by the decoder but is payload, not padding.
    nul = [i for i in ignored if i not in found]
    assert len(nul) == 1 and data[nul[0]] == 0
    assert found == set(ignored) - set(nul)
    dirty = bytearray(data)
    for i in found:
        dirty[i] = 0xAA
    assert CdrLayout(name, HOLDER).canonical(bytes(dirty) + b'\xaa\xaa') == data


def test_short_or_foreign_payloads_are_recording_errors():
    data = recorded_bytes(make_path())
    definition = message_definition('nav_msgs/msg/Path')
    with pytest.raises(RecordingError, match='nav_msgs/msg/Path'):
        canonical_cdr(data[:len(data) - 3], 'nav_msgs/msg/Path', definition)
    with pytest.raises(RecordingError, match='CDR header'):
        canonical_cdr(b'\x07\x07' + data[2:], 'nav_msgs/msg/Path', definition)
    # Bytes 12-16 are the length of header.frame_id 'map', 20-24 the number of poses.
    assert data[12:20] == b'\x04\0\0\0map\0'
    for at, what in ((12, 'string'), (20, 'elements')):
        with pytest.raises(RecordingError, match=what):
            canonical_cdr(data[:at] + b'\xff\xff\xff\x7f' + data[at + 4:],
                          'nav_msgs/msg/Path', definition)
    with pytest.raises(RecordingError, match='wstring'):
        CdrLayout('pkg/W', 'wstring name\n')


# -- a real recording ----------------------------------------------------------------------

def test_plan_record_opens_in_rosbags_anyreader_and_every_message_decodes(tmp_path):
    out = tmp_path / 'rec.mcap'
    subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'plan',
                    str(REPO / 'test/data/uniform20_0.yaml'), '--record', str(out)],
                   check=True, capture_output=True, cwd=REPO)
    seen = {}
    with AnyReader([out]) as reader:  # the file's own definitions
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            jazzy = JAZZY.deserialize_cdr(raw, connection.msgtype)
            assert plain(msg) == plain(jazzy)
            seen[connection.topic] = seen.get(connection.topic, 0) + 1
    assert seen == {'/parameter_events': 1, '/start': 1, '/goal_pose': 1, '/threats': 1,
                    '/initial_path': 1, '/path': 1, '/network': 1, '/plan_info': 1}
