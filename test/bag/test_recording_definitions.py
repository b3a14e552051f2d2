"""Tests of the bag writer's message definitions: the rosbag2 layout, parsed both ways."""

from pathlib import Path
import sys

from mcap_ros2._dynamic import generate_dynamic
import pytest
from rosbags.typesys import get_types_from_msg

from bag_samples import SEPARATOR
from threat_planner.bag import McapRecorder, message_definition, msg_dependencies
from threat_planner.bag.definitions import _build_definition
from threat_planner.errors import RecordingError

REQUIRED_TYPES = [
    'sensor_msgs/msg/PointCloud2', 'geometry_msgs/msg/PoseArray',
    'geometry_msgs/msg/PoseStamped', 'nav_msgs/msg/Path',
    'visualization_msgs/msg/MarkerArray', 'diagnostic_msgs/msg/DiagnosticArray',
    'rcl_interfaces/msg/ParameterEvent',
]


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
