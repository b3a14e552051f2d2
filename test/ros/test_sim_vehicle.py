"""The ``sim_vehicle`` node and the threat publisher's events playback, as real processes.

The vehicle flies a straight path, then a U-turn far tighter than its turn radius, at
40 m/s and 20 Hz; every odom is checked from the positions alone: 2 m steps, the
orientation along the step just flown, the twist [speed, 0, 0] in base_link, and no three
consecutive positions on a circle smaller than min_turn_radius_m.
"""

import math
import subprocess

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path as PathMsg
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray
import yaml

from node_harness import (domain_id, LATCHED, LATCHED_LOG, PYTHON, REPO, RosClient,
                          ros_env, start_process, stop_process)
from threat_planner.core.flight.reference import ReferencePath
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.trajectory import quaternion_yaw_pitch
from threat_planner.flight.follow import join
from threat_planner.ros.conversions import (moving_threats_from_pointcloud2, path_to_msg,
                                            stamp_to_ns)
from threat_planner.ros.conversions.airspace import zones_from_markers
from threat_planner.ros.publisher import EXIT_BAD_EVENTS

DOMAIN = domain_id(101)
SPEED, RATE, RADIUS = 40.0, 20.0, 20.0
STEP = SPEED / RATE
SCENARIO_FILE = REPO / 'test' / 'data' / 'uniform20_0.yaml'
ODOM_LOG = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE,
                      history=HistoryPolicy.KEEP_LAST, depth=200)
VEHICLE = [PYTHON, '-m', 'threat_planner.ros.sim_vehicle']
PUBLISHER = [PYTHON, '-m', 'threat_planner.ros.publisher']


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'sim_vehicle_test')
    yield c
    c.close()


@pytest.fixture(scope='module')
def vehicle(client, tmp_path_factory):
    ns = '/sv'
    tmp_path = tmp_path_factory.mktemp('sim_vehicle')
    proc = start_process(VEHICLE + [
        '--ros-args', '-r', f'__ns:={ns}', '-p', f'speed_mps:={SPEED}',
        '-p', f'rate_hz:={RATE}', '-p', f'min_turn_radius_m:={RADIUS}',
        '-p', 'start:=[0.0, 0.0, 50.0]', '-p', 'start_heading:=[0.0, 0.0]'],
        DOMAIN, tmp_path / 'sim_vehicle.log')
    client.subscribe(f'{ns}/odom', Odometry, ODOM_LOG)
    path_pub = client.publisher(f'{ns}/path', PathMsg, LATCHED)
    try:
        client.wait_for(f'{ns}/odom', timeout=30.0)
        yield ns, proc, path_pub
    finally:
        assert stop_process(proc) == 0, (tmp_path / 'sim_vehicle.log').read_text()
        client.unsubscribe(f'{ns}/odom')


def _state(msg):
    p = msg.pose.pose.position
    q = msg.pose.pose.orientation
    yaw, pitch = quaternion_yaw_pitch([q.x, q.y, q.z, q.w])[0]
    nose = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                     math.sin(pitch)])
    return np.array([p.x, p.y, p.z]), nose


def _circumradius(a, b, c):
    ab, bc, ca = np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c)
    area2 = np.linalg.norm(np.cross(b - a, c - a))
    return math.inf if area2 < 1e-12 else ab * bc * ca / (2.0 * area2)


def _check_stream(msgs):
    """Every odom's frames and twist; steps, headings and turns of consecutive ones."""
    states = [_state(m) for m in msgs]
    for m in msgs:
        assert (m.header.frame_id, m.child_frame_id) == ('map', 'base_link')
        t = m.twist.twist.linear
        assert (t.x, t.y, t.z) == (SPEED, 0.0, 0.0)
    positions = np.array([p for p, _ in states])
    steps = np.diff(positions, axis=0)
    np.testing.assert_allclose(np.linalg.norm(steps, axis=1), STEP, rtol=0, atol=1e-9)
    for (p, nose), step in zip(states[1:], steps):
        assert np.degrees(math.acos(min(1.0, nose @ step / STEP))) < 1e-5
    radii = [_circumradius(*positions[k:k + 3]) for k in range(len(positions) - 2)]
    assert min(radii) >= RADIUS, min(radii)
    return positions, radii


def _odoms(client, topic, first, count, timeout=20.0):
    """Messages `first` .. `first` + `count` - 1 of `topic`, waited for."""
    client.wait_until(lambda: client.count(topic) >= first + count, timeout,
                      f'{count} odom messages')
    return [m for _, m in client.messages[topic][first:first + count]]


def test_vehicle_flies_a_straight_path_then_a_tight_turn_within_its_limits(client, vehicle):
    ns, _, path_pub = vehicle
    topic = f'{ns}/odom'
    # Before any path: straight on from the start along +x.
    first = _odoms(client, topic, 0, 5)
    positions, _ = _check_stream(first)
    np.testing.assert_allclose(positions[:, 1:], [[0.0, 50.0]] * 5, atol=1e-9)
    # A straight path 45 deg to the left, from just ahead of the vehicle: joined in a
    # turn no tighter than R, then followed straight.
    here, _ = _state(client.last(topic))
    d = np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0])
    start = here + [10.0, 0.0, 0.0]
    path_pub.publish(path_to_msg(np.array([start, start + 2000.0 * d]), 'map',
                                 client.node.get_clock().now().to_msg()))
    straight = _odoms(client, topic, client.count(topic) - 1, 51)
    positions, _ = _check_stream(straight)
    off = np.cross(positions[-10:] - start, d)
    assert np.abs(off).max() < 0.05, off        # on the line after 2.5 s
    _, nose = _state(straight[-1])
    assert nose @ d > math.cos(math.radians(0.5))
    # A U-turn of radius 5 m: flown on a circle of at least R, back along -d.
    here, _ = _state(client.last(topic))
    side = np.array([-d[1], d[0], 0.0])
    arc = [here + 20.0 * d + 5.0 * (side - math.cos(a) * side + math.sin(a) * d)
           for a in np.linspace(0.0, math.pi, 13)]
    back = arc[-1] - 1500.0 * d
    path_pub.publish(path_to_msg(np.array([here + d] + arc + [back]), 'map',
                                 client.node.get_clock().now().to_msg()))
    turn = _odoms(client, topic, client.count(topic) - 1, 101)
    positions, radii = _check_stream(turn)
    assert min(radii) < 1.05 * RADIUS       # the turn is at the limit, not wider
    _, nose = _state(turn[-1])
    assert nose @ -d > math.cos(math.radians(1.0))
    off = np.linalg.norm(np.cross(positions[-5:] - back, d), axis=1)
    assert off.max() < 0.5, off


@pytest.mark.parametrize('name, value, words', [
    ('speed_mps', 0.0, 'speed_mps: must be finite and > 0'),
    ('speed_mps', -5.0, 'speed_mps'),
    ('rate_hz', 0.0, 'rate_hz: must be finite and 0 < rate_hz <= 1000, got 0.0'),
    ('min_turn_radius_m', math.nan, 'min_turn_radius_m'),
    ('max_climb_deg', 0.0, 'max_climb_deg: must be finite and > 0 and <= 90, got 0.0'),
    ('start', [1.0, 2.0], 'start: expected [x, y, z]'),
    ('start_heading', [0.0, 120.0], 'start_heading: pitch must be within -90..90 deg, '
                                    'got 120'),
    ('frame_id', '', 'frame_id'),
])
def test_vehicle_refuses_bad_parameters_with_the_reason(client, vehicle, name, value, words):
    ns, proc, _ = vehicle
    result, = client.set_parameters(f'{ns}/sim_vehicle', {name: value})
    assert not result.successful and words in result.reason, result.reason
    ok, = client.set_parameters(f'{ns}/sim_vehicle', {'rate_hz': RATE})
    assert ok.successful
    _check_stream(_odoms(client, f'{ns}/odom', client.count(f'{ns}/odom') - 1, 6))
    assert proc.poll() is None


def test_vehicle_refuses_to_start_with_a_bad_parameter():
    p = subprocess.run(VEHICLE + ['--ros-args', '-p', 'start_heading:=[0.0, -91.0]'],
                       cwd=REPO, env=ros_env(DOMAIN), capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 1
    assert 'start_heading: pitch must be within -90..90 deg, got -91' in p.stdout + p.stderr


def _events_file(tmp_path, events):
    f = tmp_path / 'events.yaml'
    f.write_text(yaml.safe_dump({'events': events}))
    return f


def test_publisher_plays_a_popup_a_move_and_a_goal_at_their_times(client, tmp_path):
    ns = '/tp'
    popup = [55.0, 45.0, 90.0]
    events = _events_file(tmp_path, [
        {'t': 0.6, 'move_threat': {'index': 2, 'velocity': [10.0, 0.0, 0.0]}},
        {'t': 1.5, 'add_threat': {'position': popup, 'intensity': 2.0e5,
                                  'lethal_radius': 6.0}},
        {'t': 1.8, 'goal': [90.0, 80.0, 60.0]},
    ])
    client.subscribe(f'{ns}/threats', PointCloud2, LATCHED_LOG)
    client.subscribe(f'{ns}/goal_pose', PoseStamped, LATCHED_LOG)
    proc = start_process(PUBLISHER + ['--ros-args', '-r', f'__ns:={ns}', '-p',
                                      f'scenario:={SCENARIO_FILE}', '-p',
                                      f'events_file:={events}'],
                         DOMAIN, tmp_path / 'publisher.log')
    try:
        goal = client.wait_for(f'{ns}/goal_pose', lambda m: m.pose.position.x == 90.0, 30.0)
        first = stamp_to_ns(client.messages[f'{ns}/threats'][0][1].header.stamp)
        client.wait_for(f'{ns}/threats',
                        lambda m: stamp_to_ns(m.header.stamp) >= first + 2_400_000_000, 10.0)
        pictures = [m for _, m in client.messages[f'{ns}/threats']]
    finally:
        assert stop_process(proc) == 0, (tmp_path / 'publisher.log').read_text()
    log = (tmp_path / 'publisher.log').read_text()
    scenario = load_scenario(SCENARIO_FILE)
    t0 = stamp_to_ns(pictures[0].header.stamp)
    times = [(stamp_to_ns(m.header.stamp) - t0) * 1e-9 for m in pictures]
    clouds = [moving_threats_from_pointcloud2(m, 'map') for m in pictures]
    np.testing.assert_allclose(clouds[0][0], scenario.threats.positions, atol=1e-4)
    sizes = [len(c[0]) for c in clouds]
    first_popup = sizes.index(21)
    assert set(sizes[:first_popup]) == {20} and set(sizes[first_popup:]) == {21}, sizes
    assert 1.45 <= times[first_popup] < 1.75, times
    np.testing.assert_allclose(clouds[first_popup][0][20], popup, atol=1e-4)
    assert clouds[first_popup][1][20] == 2.0e5
    # Threat 2 moves at 10 m/s from 0.6 s, republished at 2 Hz (at least) as it does.
    moving = [k for k, t in enumerate(times) if t >= 0.6]
    assert len(moving) >= 3 and max(np.diff([times[k] for k in moving])) < 0.7, times
    x0 = scenario.threats.positions[2, 0]
    assert all(clouds[k][2] is None for k in range(len(times)) if k not in moving)
    for k in moving:    # the cloud carries the velocities: threat 2's, zeros for the rest
        vel = np.zeros((len(clouds[k][0]), 3))
        vel[2, 0] = 10.0
        np.testing.assert_array_equal(clouds[k][2], vel)
        assert clouds[k][0][2, 0] == pytest.approx(x0 + 10.0 * (times[k] - 0.6), abs=0.3)
        np.testing.assert_allclose(np.delete(clouds[k][0][:20], 2, 0),
                                   np.delete(scenario.threats.positions, 2, 0), atol=1e-4)
    assert (stamp_to_ns(goal.header.stamp) - t0) * 1e-9 >= 1.8
    assert 'event: add_threat at t=1.5' in log


def test_publisher_plays_an_added_zone_on_no_fly_zones(client, tmp_path):
    ns = '/tpz'
    events = _events_file(tmp_path, [
        {'t': 0.8, 'add_zone': {'type': 'sphere', 'center': [50.0, 50.0, 70.0],
                                'radius': 9.0}},
        {'t': 1.2, 'add_zone': {'type': 'sphere', 'center': [30.0, 60.0, 40.0],
                                'radius': 4.0}},
    ])
    client.subscribe(f'{ns}/threats', PointCloud2, LATCHED_LOG)
    client.subscribe(f'{ns}/no_fly_zones', MarkerArray, LATCHED_LOG)
    proc = start_process(PUBLISHER + ['--ros-args', '-r', f'__ns:={ns}', '-p',
                                      f'scenario:={SCENARIO_FILE}', '-p',
                                      f'events_file:={events}'],
                         DOMAIN, tmp_path / 'publisher.log')
    try:
        client.wait_for(f'{ns}/no_fly_zones',
                        lambda m: len(zones_from_markers(m, 'map')) == 2, 30.0)
        first = stamp_to_ns(client.messages[f'{ns}/threats'][0][1].header.stamp)
        arrays = [m for _, m in client.messages[f'{ns}/no_fly_zones']]
    finally:
        assert stop_process(proc) == 0, (tmp_path / 'publisher.log').read_text()
    zones = [zones_from_markers(m, 'map') for m in arrays]
    assert [len(z) for z in zones] == [1, 2]
    times = [(stamp_to_ns(m.markers[-1].header.stamp) - first) * 1e-9 for m in arrays]
    assert 0.75 <= times[0] < 1.2 and times[1] >= 1.15, times
    # The second message still holds the first zone: a message replaces the planner's.
    assert zones[1][0].inside(np.array([[50.0, 50.0, 70.0]]))[0]
    assert zones[1][1].inside(np.array([[30.0, 60.0, 40.0]]))[0]


@pytest.mark.parametrize('events, words', [
    ([{'t': 1.0, 'add_threat': {'position': [1.0, 2.0, 3.0], 'intensity': -5.0}}],
     'events[0].add_threat.intensity: must be > 0, got -5'),
    ([{'t': 1.0, 'remove_threat': {'index': 25}}],
     'events[0].remove_threat.index: threat 25 does not exist'),
    ([{'t': 2.0, 'goal': [1.0, 2.0, 3.0]}, {'t': 1.0, 'goal': [1.0, 2.0, 3.0]}],
     'events[1].t: 1 is before events[0].t 2'),
])
def test_publisher_refuses_a_bad_events_file_in_one_line_exit_2(tmp_path, events, words):
    f = _events_file(tmp_path, events)
    p = subprocess.run(PUBLISHER + ['--ros-args', '-p', f'scenario:={SCENARIO_FILE}',
                                    '-p', f'events_file:={f}'],
                       cwd=REPO, env=ros_env(DOMAIN), capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == EXIT_BAD_EVENTS, p.stdout + p.stderr
    lines = [line for line in (p.stdout + p.stderr).splitlines()
             if 'DDS discovery' not in line]
    assert len(lines) == 1 and words in lines[0], lines


def test_a_new_path_is_joined_at_the_nearest_point_the_first_time_it_passes():
    ref = ReferencePath([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [100.0, 30.0, 0.0],
                         [50.0, 30.0, 0.0], [50.0, 0.3, 0.0], [50.0, -50.0, 0.0]])
    assert join(ref, np.array([30.0, 2.0, 0.0])) == pytest.approx(30.0)
    # Nearest on the way back (0.2 m off), but 0.5 m off on the way out: the first pass.
    assert join(ref, np.array([50.0, 0.5, 0.0])) == pytest.approx(50.0)
    assert ref.project(np.array([50.0, 0.5, 0.0]), 0.0, ref.length) > 200.0
    assert join(ref, np.array([50.0, -20.0, 0.0])) == pytest.approx(209.7 + 20.3)
