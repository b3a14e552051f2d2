"""Issue 14 over the real middleware: typed parameters, plain reasons, a responsive node.

* every parameter has one type, from its setting: a value of another type (``bounds`` as
  strings, an integer for a double) is refused with the reason at run time, and an
  integer array for ``bounds`` on the command line stops the node with one line;
* inputs with coordinates beyond the limit of :mod:`threat_planner.core.world.threats` are
  refused naming the limit, not as an unreachable goal;
* a ``frame_id`` change drops the threat picture of the old frame and says so.
"""

import signal

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseArray
import pytest
from rcl_interfaces.msg import ParameterType

from node_harness import (cloud, domain_id, info, planner_command, PlannerNode, pose, REPO,
                          RosClient, start_process, stop_process)
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.inputs.settings import NODE_SETTINGS
from threat_planner.core.world.threats import as_point, COORDINATE_LIMIT_M, ThreatField
from threat_planner.errors import InputError
from threat_planner.ros.conversions import stamp_to_ns
from threat_planner.ros.parameters import descriptor

DOMAIN = domain_id(61)
SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')
FAST = {'method': 'paper', 'start': SCENARIO.start.tolist(), 'goal': SCENARIO.goal.tolist(),
        'bounds': SCENARIO.box.lo.tolist() + SCENARIO.box.hi.tolist()}
TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
         float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING,
         list: ParameterType.PARAMETER_DOUBLE_ARRAY}


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'reliability_client')
    yield c
    c.close()


@pytest.fixture(scope='module')
def node(client, tmp_path_factory):
    n = PlannerNode(client, DOMAIN, '/rel', FAST, tmp_path_factory.mktemp('rel') / 'node.log',
                    SCENARIO)
    yield n
    assert stop_process(n.proc, signal.SIGTERM) == 0, n.log()
    assert 'Traceback' not in n.log(), n.log()


def test_every_descriptor_has_the_type_of_its_setting():
    for name, setting in NODE_SETTINGS.items():
        desc = descriptor(name)
        assert desc.type == TYPES[setting.kind], name
        assert not desc.dynamic_typing, name


@pytest.mark.parametrize('name, value', [
    ('bounds', ['0.0', '0.0', '0.0', '100.0', '100.0', '100.0']),
    ('bounds', [0, 0, 0, 100, 100, 100]),
    ('start', 'near the gate'),
    ('w', 1),
    ('n_points', 40.0),
    ('auto_k', 'true'),
    ('frame_id', 7),
    ('record', False),
])
def test_a_value_of_another_type_is_refused_with_the_reason(client, node, name, value):
    result = client.set_parameters(node.name, {name: value})[0]
    assert not result.successful
    # rclpy's own reason, before the node's callback: it names the declared type.
    declared = {bool: 'BOOL', int: 'INTEGER', float: 'DOUBLE', str: 'STRING',
                list: 'DOUBLE_ARRAY'}[NODE_SETTINGS[name].kind]
    assert 'Wrong parameter type' in result.reason, result.reason
    assert f"expected 'Type.{declared}'" in result.reason, result.reason
    assert client.set_parameters(node.name, {"w": 0.5})[0].successful  # still answering


def test_integer_array_on_the_command_line_is_refused_in_one_line(tmp_path):
    log = tmp_path / 'node.log'
    proc = start_process(planner_command('/rel_int', {'bounds': [0, 0, 0, 100, 100, 100]}),
                         DOMAIN, log)
    assert proc.wait(30) == 1
    text = log.read_text()
    lines = [line for line in text.splitlines() if 'cannot start' in line]
    assert len(lines) == 1 and 'bounds' in lines[0], text
    assert 'Traceback' not in text, text


# ------------------------------------------------------------------ reasons


def test_coordinate_limit_is_named_in_the_core():
    with pytest.raises(InputError, match=r'threats\[1\]: coordinate 1\.7e\+308 m is too large '
                                         r'for double-precision geometry; .* <= 1e\+12 m'):
        ThreatField.from_arrays([[1.0, 2.0, 3.0], [0.0, 1.7e308, 0.0]], [1.0, 1.0])
    with pytest.raises(InputError, match=r'^start: coordinate 2e\+12 m is too large'):
        as_point('start', [0.0, -2e12, 0.0])
    # The limit itself is allowed.
    assert len(ThreatField.from_arrays([[COORDINATE_LIMIT_M, 0.0, 0.0]], [1.0])) == 1


def pose_array(points, frame='map', stamp=None):
    msg = PoseArray()
    msg.header.frame_id = frame
    msg.header.stamp = stamp or Time()
    for x, y, z in points:
        p = Pose()
        p.position.x, p.position.y, p.position.z = float(x), float(y), float(z)
        p.orientation.w = 1.0
        msg.poses.append(p)
    return msg


def test_huge_coordinates_are_refused_naming_the_limit(node):
    node.answer(node.picture())
    far = SCENARIO.threats.positions.tolist()
    far[3] = [1.7e308, 50.0, 50.0]
    stamp = node.stamp()
    node.poses.publish(pose_array(far, stamp=stamp))
    i = node.answer(stamp.sec)
    assert i['level'] == 'ERROR'
    assert 'too large for double-precision geometry' in i['error'], i['error']
    assert '1e+12 m' in i['error'] and 'reachable' not in i['error']
    stamp = node.stamp()
    node.threats.publish(cloud(far[:3] + [[1e30, 0.0, 0.0]], [1.0] * 4, stamp=stamp))
    i = node.answer(stamp.sec)
    assert i['level'] == 'ERROR' and 'threats[3]: coordinate 1e+30 m' in i['error'], i
    stamp = node.stamp()
    node.start.publish(pose([1.7e308, 0.0, 0.0], stamp=stamp))
    i = node.answer(stamp.sec)
    assert i['level'] == 'ERROR' and 'start: coordinate 1.7e+308 m' in i['error'], i


def test_frame_change_drops_the_old_picture_and_says_so(client, node):
    node.answer(node.picture())
    assert client.set_parameters(node.name, {'frame_id': 'odom'})[0].successful
    i = info(client.wait_for(f'{node.ns}/plan_info',
                             lambda m: info(m).get('threats_dropped') == 'true'))
    assert i['level'] == 'WARN' and "from 'map' to 'odom'" in i['message'], i
    # No plan from the old picture: the next plan answers a picture in the new frame.
    stamp = node.stamp()
    node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                               frame_id='map', stamp=stamp))
    assert node.answer(stamp.sec)['level'] == 'ERROR'
    stamp = node.stamp()
    node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                               frame_id='odom', stamp=stamp))
    i = node.answer(stamp.sec)
    assert 'J' in i and i['frame_id'] == 'odom', i
    path = client.wait_for(f'{node.ns}/path',
                           lambda m: stamp_to_ns(m.header.stamp) == int(i['t0_ns']))
    assert path.header.frame_id == 'odom'
    assert client.set_parameters(node.name, {'frame_id': 'map'})[0].successful
