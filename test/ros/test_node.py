"""Tests of the planner node and the threat publisher over the real ROS 2 middleware.

Each node runs as its own process (``python -m threat_planner.ros.node``) in a
namespace of this module's ROS domain; this process talks to them through its own rclpy
context (see node_harness.py). Planner settings are fast ('paper') wherever the result
itself is not under test; the comparison with the library uses the default 'best'.
"""

import math
import signal
import time

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import MarkerArray

from node_fixtures import (_inten, _pos, _pose_array, DEEP_LATCHED, DOMAIN, expected_plan,
                           FAST_MAX_THREATS, node_parameters, PlannerProcess, raw_cloud,
                           run_in_thread, SCENARIO, SCENARIO_FILE, scenario_params)
from node_harness import cloud, pose, PYTHON, RosClient, start_process, stop_process
from threat_planner.core.planner import plan
from threat_planner.core.world.threats import ThreatField
from threat_planner.ros.conversions import path_from_msg, stamp_to_ns
from threat_planner.ros.parameters import PARAMETER_DEFAULTS, settings_from_parameters


# ------------------------------------------------------------------- fixtures


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'test_node_client')
    yield c
    c.close()


@pytest.fixture(scope='module')
def best_node(client, tmp_path_factory):
    """Default ('best') settings from config/planner.yaml, start and goal of the scenario."""
    node = PlannerProcess(client, '/best', scenario_params(),
                          tmp_path_factory.mktemp('best') / 'node.log')
    yield node
    assert node.stop(signal.SIGINT) == 0, node.log()


@pytest.fixture(scope='module')
def fast_node(client, tmp_path_factory):
    """'paper' settings, a small max_threats, default start and goal ([0,0,50], [100,100,50])."""
    node = PlannerProcess(client, '/fast', {'method': 'paper', 'max_threats': FAST_MAX_THREATS},
                          tmp_path_factory.mktemp('fast') / 'node.log')
    yield node
    assert node.stop() == 0, node.log()


# ------------------------------------------------------ planning with 'best'


def test_plan_matches_library(best_node):
    msg = cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                stamp=Time(sec=3, nanosec=5))
    expected = run_in_thread(expected_plan, msg, SCENARIO.start, SCENARIO.goal,
                             node_parameters(**scenario_params()))
    best_node.threats.publish(msg)
    i, path, initial = best_node.wait_plan(after_seq=0)
    result = expected()

    assert i['input_seq'] == '1' and i['input_source'] == '/best/threats'
    assert int(i['input_stamp_ns']) == 3_000_000_005
    assert i['method'] == 'best' and i['threats'] == '20'
    np.testing.assert_allclose(path_from_msg(initial), result.initial_path, rtol=0, atol=1e-6)
    np.testing.assert_allclose(path_from_msg(path), result.path, rtol=0, atol=1e-6)
    assert float(i['J']) == pytest.approx(result.cost.J, rel=1e-9)
    assert float(i['initial_J']) == pytest.approx(result.initial_cost.J, rel=1e-9)
    for key in ('J_L', 'J_R', 'initial_J_L', 'initial_J_R', 'nodes', 'edges', 'entry', 'exit',
                'k', 'feasible', 'partition_ms', 'search_ms', 'total_ms', 'inputs_skipped'):
        assert key in i, key
    assert int(i['nodes']) == result.network.n_nodes
    assert i['feasible'] == str(result.feasible)
    assert i['level'] == ('OK' if result.feasible else 'WARN')
    for m in (path, initial):   # stamped with the plan's t0; the markers with the input's
        assert m.header.frame_id == 'map' and stamp_to_ns(m.header.stamp) == int(i['t0_ns'])
        # a trajectory: pose k at t0 + its arc length / speed_mps (20 m/s)
        points = path_from_msg(m)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0),
                                                              axis=1))])
        after = np.array([stamp_to_ns(p.header.stamp) for p in m.poses]) - int(i['t0_ns'])
        np.testing.assert_allclose(after, 1e9 * arc / 20.0, rtol=0, atol=1.0)
    assert float(i['speed_mps']) == 20.0
    assert float(i['eta_s']) == pytest.approx(result.cost.J_L / 20.0, rel=1e-9)
    net = best_node.client.wait_for(best_node.topic('network'),
                                    lambda m: m.markers[0].header.stamp == msg.header.stamp)
    assert {m.ns for m in net.markers} >= {'threats', 'nodes', 'network', 'path'}


def test_late_subscriber_gets_latched_plan(best_node):
    client = best_node.client
    last = client.last(best_node.topic('path'))
    late = RosClient(DOMAIN, 'late_subscriber')
    try:
        for name, msg_type in (('path', PathMsg), ('initial_path', PathMsg),
                               ('plan_info', DiagnosticArray), ('network', MarkerArray)):
            late.subscribe(best_node.topic(name), msg_type)
            late.wait_for(best_node.topic(name), timeout=10.0)
        got = late.messages[best_node.topic('path')]
        assert len(got) == 1
        assert got[0][1].header.stamp == last.header.stamp
        np.testing.assert_array_equal(path_from_msg(got[0][1]), path_from_msg(last))
    finally:
        late.close()


# --------------------------------------------------------- the fast node


def baseline(fast_node):
    """Publish the scenario's threats to the fast node and return its plan."""
    seq = fast_node.last_seq()
    fast_node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                    stamp=Time(sec=10)))
    return fast_node.wait_plan(after_seq=seq)


def test_start_and_goal_messages_replan(fast_node):
    baseline(fast_node)
    for sec, pub, xyz, end in ((11, fast_node.start, [5.0, 10.0, 40.0], 0),
                               (12, fast_node.goal, [90.0, 95.0, 60.0], -1)):
        seq = fast_node.last_seq()
        pub.publish(pose(xyz, stamp=Time(sec=sec)))
        i, path, initial = fast_node.wait_plan(after_seq=seq)
        assert i['input_source'].endswith(('/start', '/goal_pose'))
        np.testing.assert_allclose(path_from_msg(path)[end], xyz, atol=1e-9)
        np.testing.assert_allclose(path_from_msg(initial)[end], xyz, atol=1e-9)
    # Back to the defaults for the tests that follow.
    for sec, pub, xyz in ((13, fast_node.start, [0.0, 0.0, 50.0]),
                          (14, fast_node.goal, [100.0, 100.0, 50.0])):
        seq = fast_node.last_seq()
        pub.publish(pose(xyz, stamp=Time(sec=sec)))
        fast_node.wait_plan(after_seq=seq)


def test_replans_after_threat_update(fast_node):
    _, before, _ = baseline(fast_node)
    moved = SCENARIO.threats.positions + np.array([3.0, -2.0, 1.5])
    msg = cloud(moved, SCENARIO.threats.intensities, stamp=Time(sec=15))
    seq = fast_node.last_seq()
    fast_node.threats.publish(msg)
    i, path, _ = fast_node.wait_plan(after_seq=seq)
    assert int(i['input_seq']) == seq + 1 and int(i['input_stamp_ns']) == 15 * 10**9
    assert stamp_to_ns(path.header.stamp) == int(i['t0_ns'])
    assert not np.allclose(path_from_msg(path), path_from_msg(before))
    expected = expected_plan(msg, [0.0, 0.0, 50.0], [100.0, 100.0, 50.0],
                             node_parameters(method='paper'))
    np.testing.assert_allclose(path_from_msg(path), expected.path, rtol=0, atol=1e-6)


def test_parameter_change_replans_and_bad_values_are_refused(fast_node):
    client = fast_node.client
    seq = fast_node.last_seq()
    results = client.set_parameters(fast_node.node_name, {'w': 0.8})
    assert results[0].successful, results[0].reason
    i, path, _ = fast_node.wait_plan(after_seq=seq)
    assert i['input_source'] == 'parameters' and i['w'] == '0.8'
    assert int(i['input_seq']) == seq + 1

    refused = {
        'w': (0.0, 'w: must satisfy 0 < w < 1, got 0.0'),
        'method': ('fastest', 'method: must be one of paper, improved, best'),
        'bounds': ([0.0, 0.0, 0.0, 100.0, 100.0], 'bounds: expected 6 numbers'),
        'n_points': (1, 'out of range'),
        'start': ([0.0, 0.0, 150.0], 'start: [0.0, 0.0, 150.0] is outside bounds'),
        'frame_id': ('', 'frame_id: must be a non-empty string'),
    }
    count = client.count(fast_node.topic('plan_info'))
    for name, (value, reason) in refused.items():
        result = client.set_parameters(fast_node.node_name, {name: value})[0]
        assert not result.successful, name
        assert reason in result.reason, (name, result.reason)
    # Shrinking the box so that it no longer holds the goal is refused as a whole.
    result = client.set_parameters(fast_node.node_name, {
        'bounds': [0.0, 0.0, 0.0, 50.0, 50.0, 100.0]}, atomically=True)[0]
    assert not result.successful and 'goal:' in result.reason
    time.sleep(0.3)
    assert client.count(fast_node.topic('plan_info')) == count, 'a refused change replanned'
    assert fast_node.alive()
    seq = fast_node.last_seq()
    assert client.set_parameters(fast_node.node_name, {'w': 0.5})[0].successful
    fast_node.wait_plan(after_seq=seq)


THREAT0 = np.float32(SCENARIO.threats.positions[0]).astype(float).tolist()
WRONG_TYPE_FIELDS = [PointField(name='x', offset=0, datatype=PointField.INT32, count=1)] + [
    PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
    for k, n in enumerate(('y', 'z', 'intensity'), 1)]
NO_INTENSITY_FIELDS = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                       for k, n in enumerate(('x', 'y', 'z'))]

BAD_INPUTS = {
    'cloud_nan_position': ('threats', lambda: cloud(_pos(p3_x=math.nan), _inten()),
                           'non-finite positions'),
    'cloud_inf_position': ('threats', lambda: cloud(_pos(p0_z=math.inf), _inten()),
                           'non-finite positions'),
    'cloud_nan_intensity': ('threats', lambda: cloud(_pos(), _inten(f2=math.nan)),
                            'non-finite intensities'),
    'cloud_zero_intensity': ('threats', lambda: cloud(_pos(), _inten(f5=0.0)),
                             'non-positive intensities'),
    'cloud_negative_intensity': ('threats', lambda: cloud(_pos(), _inten(f7=-3.0)),
                                 'non-positive intensities'),
    'cloud_too_many_threats': (
        'threats', lambda: cloud(np.tile(_pos(), (3, 1)) + 0.01 * np.arange(60)[:, None],
                                 np.tile(_inten(), 3)),
        f'60 threats, more than max_threats={FAST_MAX_THREATS}'),
    'cloud_without_intensity': (
        'threats', lambda: raw_cloud(_pos(), _inten(), fields=NO_INTENSITY_FIELDS,
                                     point_step=12),
        "missing field(s) ['intensity']"),
    'cloud_wrong_field_type': ('threats', lambda: raw_cloud(_pos(), _inten(),
                                                            fields=WRONG_TYPE_FIELDS),
                               "field 'x' has datatype INT32"),
    'cloud_wrong_point_step': ('threats', lambda: raw_cloud(_pos(), _inten(), point_step=12),
                               'point_step 12 is smaller than the 16 bytes'),
    'cloud_truncated_data': ('threats', lambda: raw_cloud(_pos(), _inten(), trim=5),
                             'data has 315 bytes'),
    'cloud_wrong_frame': ('threats', lambda: cloud(_pos(), _inten(), frame_id='odom'),
                          "frame_id 'odom' does not match expected frame 'map'"),
    'cloud_threat_on_start': ('threats', lambda: cloud(_pos(p4_x=0.0, p4_y=0.0, p4_z=50.0),
                                                       _inten()),
                              'start: [0.0, 0.0, 50.0] is on threat 4'),
    'poses_nan_position': ('threat_poses', lambda: _pose_array(_pos(p1_y=math.nan)),
                           'non-finite positions'),
    'poses_too_many_threats': ('threat_poses', lambda: _pose_array(np.zeros((51, 3)) + 1.0),
                               f'51 threats, more than max_threats={FAST_MAX_THREATS}'),
    'poses_wrong_frame': ('threat_poses', lambda: _pose_array(_pos(), frame='base_link'),
                          "frame_id 'base_link' does not match"),
    'start_outside_bounds': ('start', lambda: pose([-1.0, 50.0, 50.0]),
                             'start: [-1.0, 50.0, 50.0] is outside bounds'),
    'goal_outside_bounds': ('goal_pose', lambda: pose([50.0, 50.0, 101.0]),
                            'goal: [50.0, 50.0, 101.0] is outside bounds'),
    'start_on_threat': ('start', lambda: pose(THREAT0), 'start: %s is on threat 0' % THREAT0),
    'goal_on_threat': ('goal_pose', lambda: pose(THREAT0), 'goal: %s is on threat 0' % THREAT0),
    'start_nan': ('start', lambda: pose([math.nan, 1.0, 1.0]), 'start position must be finite'),
    'goal_inf': ('goal_pose', lambda: pose([1.0, math.inf, 1.0]),
                 'goal_pose position must be finite'),
    'start_wrong_frame': ('start', lambda: pose([1.0, 1.0, 1.0], frame_id='odom'),
                          "start frame_id 'odom' does not match"),
    'goal_wrong_frame': ('goal_pose', lambda: pose([1.0, 1.0, 1.0], frame_id='odom'),
                         "goal_pose frame_id 'odom' does not match"),
}


@pytest.fixture(scope='module')
def good_plan(fast_node):
    return baseline(fast_node)


@pytest.mark.parametrize('case', list(BAD_INPUTS))
def test_bad_input_is_refused_and_last_plan_kept(fast_node, good_plan, case):
    topic, make, reason = BAD_INPUTS[case]
    client = fast_node.client
    good_info, good_path, _ = good_plan
    paths_before = client.count(fast_node.topic('path'))
    seq = fast_node.last_seq()
    pub = {'threats': fast_node.threats, 'threat_poses': fast_node.poses,
           'start': fast_node.start, 'goal_pose': fast_node.goal}[topic]
    msg = make()
    msg.header.stamp = Time(sec=100, nanosec=len(case))
    pub.publish(msg)

    i = fast_node.wait_info(after_seq=seq, timeout=10.0)
    assert i['level'] == 'ERROR', i
    assert reason in i['error'], (reason, i['error'])
    assert reason in i['message'] and fast_node.topic(topic) in i['message']
    assert int(i['input_seq']) == seq + 1
    assert int(i['input_stamp_ns']) == 100_000_000_000 + len(case)
    assert fast_node.alive()
    # The error goes to the log once, at ERROR.
    deadline = time.monotonic() + 5.0
    while f'input #{seq + 1} ' not in fast_node.log() and time.monotonic() < deadline:
        time.sleep(0.05)
    lines = [ln for ln in fast_node.log().splitlines() if f'input #{seq + 1} ' in ln]
    assert len(lines) == 1 and '[ERROR]' in lines[0] and reason in lines[0], lines
    # No new plan; the latched plan is still the last good one.
    assert client.count(fast_node.topic('path')) == paths_before
    latched = client.last(fast_node.topic('path'))
    assert latched.header.stamp == good_path.header.stamp
    np.testing.assert_array_equal(path_from_msg(latched), path_from_msg(good_path))


def test_last_good_plan_still_latched_after_bad_inputs(fast_node, good_plan):
    _, good_path, good_initial = good_plan
    late = RosClient(DOMAIN, 'late_after_errors')
    try:
        for name in ('path', 'initial_path'):
            late.subscribe(fast_node.topic(name), PathMsg)
        path = late.wait_for(fast_node.topic('path'), timeout=10.0)
        initial = late.wait_for(fast_node.topic('initial_path'), timeout=10.0)
    finally:
        late.close()
    assert path.header.stamp == good_path.header.stamp
    np.testing.assert_array_equal(path_from_msg(path), path_from_msg(good_path))
    np.testing.assert_array_equal(path_from_msg(initial), path_from_msg(good_initial))
    assert fast_node.alive()


@pytest.mark.parametrize('name, positions', [
    ('none', np.zeros((0, 3))),
    ('one', np.array([[50.0, 40.0, 60.0]])),
    ('three', np.array([[30.0, 40.0, 60.0], [60.0, 50.0, 40.0], [50.0, 70.0, 30.0]])),
    ('duplicates', np.array([[50.0, 40.0, 60.0]] * 6)),
    ('coplanar', np.array([[10.0, 80.0, 35.0], [30.0, 20.0, 35.0], [50.0, 60.0, 35.0],
                           [70.0, 10.0, 35.0], [90.0, 70.0, 35.0], [20.0, 50.0, 35.0],
                           [60.0, 90.0, 35.0], [80.0, 40.0, 35.0]])),
])
def test_degenerate_pictures_are_planned(fast_node, name, positions):
    seq = fast_node.last_seq()
    fast_node.threats.publish(cloud(positions, np.full(len(positions), 1.0e5),
                                    stamp=Time(sec=200)))
    i, path, _ = fast_node.wait_plan(after_seq=seq)
    assert int(i['input_seq']) == seq + 1, i
    assert i['threats'] == str(len(positions))
    assert len(path.poses) >= 2


def test_pose_array_threats_use_default_intensity(fast_node):
    seq = fast_node.last_seq()
    msg = _pose_array(SCENARIO.threats.positions)
    msg.header.stamp = Time(sec=300)
    fast_node.poses.publish(msg)
    i, path, _ = fast_node.wait_plan(after_seq=seq)
    assert i['input_source'] == fast_node.topic('threat_poses') and i['threats'] == '20'
    positions = SCENARIO.threats.positions
    f = np.full(len(positions), PARAMETER_DEFAULTS['default_intensity'])
    settings = settings_from_parameters(node_parameters(method='paper'))
    expected = plan(ThreatField.from_arrays(positions, f), settings.start, settings.goal,
                    settings.box, settings.config)
    np.testing.assert_allclose(path_from_msg(path), expected.path, rtol=0, atol=1e-6)


def test_flood_is_coalesced(fast_node):
    client = fast_node.client
    flood = client.publisher(fast_node.topic('threats'), PointCloud2, DEEP_LATCHED)
    client.wait_matched(flood)
    before = fast_node.infos()[-1]
    seq = int(before['input_seq'])
    n = 30
    rng = np.random.default_rng(1)
    for k in range(n):
        moved = SCENARIO.threats.positions + rng.normal(scale=0.5, size=(20, 3))
        flood.publish(cloud(moved, SCENARIO.threats.intensities, stamp=Time(sec=400 + k)))
    last = fast_node.wait_info(lambda i: int(i['input_stamp_ns']) == (400 + n - 1) * 10**9,
                               after_seq=seq, timeout=30.0)
    time.sleep(0.3)
    answered = [i for i in fast_node.infos() if int(i['input_seq']) > seq]
    assert answered[-1] == last, 'a plan was published after the one for the last input'
    received = int(last['inputs_received']) - int(before['inputs_received'])
    planned = int(last['plans_completed']) - int(before['plans_completed'])
    skipped = int(last['inputs_skipped']) - int(before['inputs_skipped'])
    assert 0 < received <= n
    assert planned == len(answered)
    # Every input was either planned or replaced while waiting: nothing queued up.
    assert planned + skipped == received
    assert skipped > 0 and planned < received
    seqs = [int(i['input_seq']) for i in answered]
    assert seqs == sorted(seqs) and seqs[-1] == seq + received


@pytest.mark.parametrize('args, topic, plans', [
    (['rate:=4.0', 'drift:=2.0', 'drift_mode:=sinusoid'], 'threats', 3),
    (['use_pose_array:=true'], 'threat_poses', 0),
], ids=['cloud_4hz_drift', 'pose_array_once'])
def test_threat_publisher_drives_replanning(fast_node, tmp_path, args, topic, plans):
    """threat_publisher, moving threats at 4 Hz or a latched PoseArray: the planner plans."""
    # Start from a node with nothing in hand: an input of the case before still waiting
    # would make the PoseArray wait too. The newest answer names the newest input then
    # (counting plans, skips and refusals would miss a start or goal stored before any
    # picture: a node started for this test alone, its publisher's start first).
    def settled():
        infos = fast_node.infos()
        return not infos or int(infos[-1]['input_seq']) == int(infos[-1]['inputs_received'])
    fast_node.client.wait_until(settled, 30.0, 'the node to answer every input so far')
    seq = fast_node.last_seq()
    paths_before = fast_node.client.count(fast_node.topic('path'))
    nets_before = fast_node.client.count(fast_node.topic('network'))
    log = tmp_path / 'publisher.log'
    cmd = [PYTHON, '-m', 'threat_planner.ros.publisher', '--ros-args', '-r', '__ns:=/fast',
           '-p', f'scenario:={SCENARIO_FILE}']
    for arg in args:
        cmd += ['-p', arg]
    proc = start_process(cmd, DOMAIN, log)
    try:
        # A picture published at 4 Hz is planned again and again under its own name.
        stamps, after = set(), seq
        while len(stamps) < plans:
            i = fast_node.wait_info(lambda i: i['input_source'] == f'/fast/{topic}'
                                    and i['level'] != 'ERROR', after_seq=after)
            stamps.add(int(i['input_stamp_ns']))
            after = int(i['input_seq'])
            assert i['threats'] == '20'
        # The publisher sends start and goal when it sees the planner subscribe; wait for
        # the plan that uses them.
        start_goal = SCENARIO.start.tolist() + SCENARIO.goal.tolist()

        def uses_scenario_ends(msg):
            ends = path_from_msg(msg)[[0, -1]].ravel()
            return np.allclose(ends, start_goal, atol=1e-9)
        fast_node.client.wait_for(fast_node.topic('path'), uses_scenario_ends, timeout=20.0,
                                  after=paths_before)
        if topic == 'threat_poses':
            # The PoseArray, sent once, may arrive while a plan for the start runs and then
            # be answered by the goal's plan (latest wins, so no plan_info need name it):
            # its plan is known by its threats, the scenario's exactly (float64, no
            # drift), where the case before left drifted float32 ones.
            def threat_positions(msg):
                spheres = sorted((m for m in msg.markers if m.ns == 'threats'),
                                 key=lambda m: m.id)
                return np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                                 for m in spheres])

            def through_the_poses(msg):
                return np.array_equal(threat_positions(msg), SCENARIO.threats.positions)
            net = fast_node.client.wait_for(fast_node.topic('network'), through_the_poses,
                                            timeout=20.0, after=nets_before)
            stamp = stamp_to_ns(next(m for m in net.markers if m.ns == 'threats').header.stamp)
            answered = fast_node.wait_info(
                lambda i: int(i['input_stamp_ns']) == stamp and i['level'] != 'ERROR',
                after_seq=seq)
            assert answered['threats'] == '20'
            assert answered['input_source'] in ('/fast/threat_poses', '/fast/start',
                                                '/fast/goal_pose')
        assert fast_node.alive()
    finally:
        assert stop_process(proc) == 0, log.read_text()
