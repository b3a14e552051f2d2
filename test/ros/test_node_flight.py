"""The node in flight (issue 44), end to end with real node processes.

One node takes odometry: a wrong frame and NaN are refused and counted (the last plan
stays latched, one ERROR plan_info per kind of reason); the first good odom plans from the
vehicle along its heading within the limits; an odom along that trajectory only tracks,
and a threat change then replans in flight: the new path's first commit_s is the old
trajectory's, its poses stamped with the splice's times. A second node plans a cloud with
vx vy vz in time: its J is the exact timed cost of the published path at its stamps.
"""

import json
import math
import time

from nav_msgs.msg import Odometry
import numpy as np
import pytest

from node_fixtures import DOMAIN, PlannerProcess, SCENARIO, scenario_params
from node_harness import cloud, RosClient, VOLATILE
from test_flight_parts import odom
from threat_planner.core.flight.reference import ReferencePath
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.world.threats import ThreatField
from threat_planner.ros.conversions import (moving_threats_from_pointcloud2, ns_to_stamp,
                                            path_from_msg, pointcloud2_from_threats,
                                            stamp_to_ns)
from threat_planner.ros.parameters import settings_from_parameters, PARAMETER_DEFAULTS

SPEED = 20.0
COMMIT_S = 2.0


@pytest.fixture
def client():
    c = RosClient(DOMAIN, 'flight_client')
    try:
        yield c
    finally:
        c.close()


def pose_times(path):
    t0 = stamp_to_ns(path.header.stamp)
    return np.array([stamp_to_ns(p.header.stamp) - t0 for p in path.poses]) * 1e-9


def arc_times(points):
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)]) / SPEED


def test_odometry_refused_then_flown_from_and_replanned_in_flight(client, tmp_path):
    node = PlannerProcess(client, '/flight', scenario_params(), tmp_path / 'node.log')
    try:
        odom_pub = client.publisher(node.topic('odom'), Odometry, VOLATILE)
        client.wait_matched(odom_pub, timeout=30.0)
        node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities))
        first, path0, _ = node.wait_plan()
        assert 'plan' not in first and first['odom_rejected'] == '0'   # a static plan
        paths = client.count(node.topic('path'))

        # Refused: another frame, then NaN twice (said once, counted twice).
        seq = node.last_seq()
        odom_pub.publish(odom([10, 10, 70], frame='odom'))
        bad = node.wait_info(lambda i: i['level'] == 'ERROR', seq)
        assert bad['odom_rejected'] == '1' and 'odom header.frame_id' in bad['error']
        nan = odom([10, 10, 70])
        nan.twist.twist.linear.y = math.nan
        odom_pub.publish(nan)
        bad = node.wait_info(lambda i: i['level'] == 'ERROR', int(bad['input_seq']))
        assert bad['odom_rejected'] == '2' and 'odom twist.twist.linear' in bad['error']
        odom_pub.publish(nan)

        # The first good odom: nose at yaw 90 deg flying along it, away from the goal's side.
        vehicle = np.array([20.0, 15.0, 70.0])
        odom_pub.publish(odom(vehicle, yaw_deg=90.0))
        info1, path1, _ = node.wait_plan(pred=lambda i: i.get('plan') == 'from_vehicle')
        assert info1['plan_reason'] == 'first odom'
        assert info1['odom_rejected'] == '3'       # the second NaN, counted silently
        assert client.count(node.topic('path')) == paths + 1, 'a refused odom replanned'
        p1 = path_from_msg(path1)
        assert np.array_equal(p1[0], vehicle)
        first_leg = (p1[1] - p1[0]) / np.linalg.norm(p1[1] - p1[0])
        assert np.linalg.norm(first_leg - [0.0, 1.0, 0.0]) < 1e-6
        assert np.allclose(json.loads(info1['start_heading']), [0, 1, 0], rtol=0, atol=1e-12)
        assert info1['entry_feasible'] == 'True' and info1['limits_feasible'] == 'True'
        config = settings_from_parameters({**PARAMETER_DEFAULTS, **scenario_params()}).config
        assert check_limits(p1, FlightLimits.of(config), 0.0).feasible
        assert np.allclose(pose_times(path1), arc_times(p1), rtol=0, atol=1e-9)

        # Along that trajectory: the odom only tracks. Then the picture changes.
        ref = ReferencePath(p1)
        along = ref.at(6.0)
        seq = node.last_seq()
        odom_pub.publish(odom(along, yaw_deg=90.0))
        moved = SCENARIO.threats.positions.copy()
        moved[0] += [0.5, -0.5, 0.0]
        time.sleep(0.2)   # the odom is taken first (the topics are not ordered)
        node.threats.publish(cloud(moved, SCENARIO.threats.intensities))
        info2, path2, _ = node.wait_plan(seq, pred=lambda i: i.get('plan') == 'in_flight')
        assert info2['input_source'].endswith('/threats')
        assert int(info2['input_seq']) == seq + 2, 'the odom along the trajectory replanned'
        p2, joint = path_from_msg(path2), int(info2['committed_points']) - 1
        committed = p2[:joint + 1]
        # The committed stretch is the old trajectory: its vertices bit for bit, its ends on
        # its segments, commit_s long at the cruise speed.
        s0 = ref.project(committed[0], 0.0, ref.length)
        s1 = s0 + SPEED * COMMIT_S
        assert 6.0 <= s0 < 6.0 + SPEED * 1.0, s0        # where the vehicle is by t0
        assert np.array_equal(committed[1:-1], ref.points[(ref.s > s0) & (ref.s < s1)])
        assert np.linalg.norm(committed[0] - ref.at(s0)) < 1e-9
        assert np.linalg.norm(committed[-1] - ref.at(s1)) < 1e-9
        assert float(info2['committed_m']) == pytest.approx(SPEED * COMMIT_S, abs=1e-9)
        # Its poses follow the splice's times: from the vehicle at t0 at the cruise speed,
        # the replan leaving the joint along the old trajectory.
        assert np.allclose(pose_times(path2), arc_times(p2), rtol=0, atol=1e-9)
        assert float(info2['replan_t_s']) == pytest.approx(COMMIT_S, abs=1e-9)
        leg = p2[joint + 1] - p2[joint]
        assert np.linalg.norm(np.cross(leg / np.linalg.norm(leg), ref.tangent(s1))) < 1e-9
        assert info2['entry_feasible'] == 'True' and info2['limits_feasible'] == 'True'
        assert node.alive()
    finally:
        assert node.stop() == 0, node.log()[-3000:]


def test_a_cloud_of_moving_threats_is_planned_in_time(client, tmp_path):
    node = PlannerProcess(client, '/moving', scenario_params(), tmp_path / 'node.log')
    try:
        vel = np.zeros((len(SCENARIO.threats), 3))
        vel[[1, 5, 9]] = [[6.0, -4.0, 0.0], [-10.0, 0.0, 2.0], [0.0, 12.0, 0.0]]
        bad = vel.copy()
        bad[5, 0] = math.nan
        seq = node.last_seq()
        node.threats.publish(pointcloud2_from_threats(
            SCENARIO.threats.positions, SCENARIO.threats.intensities, 'map',
            ns_to_stamp(time.time_ns()), bad))
        refused = node.wait_info(lambda i: i['level'] == 'ERROR', seq)
        assert "field 'vx'" in refused['error']
        stamp_ns = time.time_ns() - 300_000_000      # positions 0.3 s old
        msg = pointcloud2_from_threats(SCENARIO.threats.positions,
                                       SCENARIO.threats.intensities, 'map',
                                       ns_to_stamp(stamp_ns), vel)
        node.threats.publish(msg)
        info, path, _ = node.wait_plan(pred=lambda i: i.get('plan') == 'timed')
        assert info['moving_threats'] == '3'
        points, times = path_from_msg(path), pose_times(path)
        assert np.array_equal(points[0], SCENARIO.start)
        # J is the exact timed cost of the published path at its stamps, the threats where
        # they are when the UAV passes: the cloud's positions hold at its stamp.
        pos, f, v = moving_threats_from_pointcloud2(msg, 'map')
        t_cloud = 1e-9 * (stamp_ns - int(info['t0_ns']))
        assert -1.0 < t_cloud < 0.0
        timeline = ThreatTimeline(ThreatField.from_arrays(pos, f), v, t0=t_cloud)
        cost = timed_path_cost(points, times, timeline, 0.5)
        assert float(info['J']) == pytest.approx(cost.J, rel=1e-9)
        assert float(info['J_R']) == pytest.approx(cost.J_R, rel=1e-9)
        frozen = timed_path_cost(points, times, ThreatTimeline(ThreatField.from_arrays(pos, f)),
                                 0.5)
        assert frozen.J != pytest.approx(cost.J, rel=1e-6), 'the threats did not move'
    finally:
        assert node.stop() == 0, node.log()[-3000:]
