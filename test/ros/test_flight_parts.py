"""The node's flight parts without a node: odometry, moving clouds, the replan rule, GetPlan.

Odometry (ros/conversions/odom.py): the twist turned from the body frame into frame_id,
the nose below 0.5 m/s, every bad field named. Clouds with vx vy vz (ros/conversions/
cloud.py). The tracker's rule (ros/flight.py): the first odom replans, the next ones track,
off track replans, at most once a second; refusals counted, said once per kind of reason.
GetPlan through moving threats (ros/plan_service.py) plans in time.
"""

import math
import time

from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
from nav_msgs.srv import GetPlan
import numpy as np
import pytest

from node_fixtures import SCENARIO, scenario_params
from node_harness import pose
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.errors import InputError
from threat_planner.ros.conversions import (moving_threats_from_pointcloud2, ns_to_stamp,
                                            path_from_msg, pointcloud2_from_threats,
                                            stamp_to_ns, threats_from_pointcloud2,
                                            vehicle_from_odometry)
from threat_planner.ros.flight import FlightTracker, ODOM_DRIFT_M
from threat_planner.ros.inputs import accept, InputState
from threat_planner.ros.parameters import PARAMETER_DEFAULTS
from threat_planner.ros.plan_service import plan_on_request


def odom(position, yaw_deg=0.0, body_velocity=(20.0, 0.0, 0.0), frame='map',
         child='base_link', pitch_deg=0.0):
    """An Odometry at `position`, nose at yaw/pitch, the twist in the body frame."""
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = frame, child
    p = msg.pose.pose.position
    p.x, p.y, p.z = (float(v) for v in position)
    y, t = math.radians(yaw_deg) / 2, -math.radians(pitch_deg) / 2   # REP-103: +pitch = down
    q = msg.pose.pose.orientation
    q.x, q.y, q.z, q.w = (-math.sin(y) * math.sin(t), math.cos(y) * math.sin(t),
                          math.sin(y) * math.cos(t), math.cos(y) * math.cos(t))
    v = msg.twist.twist.linear
    v.x, v.y, v.z = (float(c) for c in body_velocity)
    return msg


def test_the_heading_is_the_velocity_turned_into_frame_id():
    v = vehicle_from_odometry(odom([1, 2, 3], 90.0, (20.0, 0.0, 0.0)), 'map')
    np.testing.assert_allclose(v.heading, [0, 1, 0], atol=1e-12)
    assert v.speed == pytest.approx(20.0) and v.from_velocity
    # Nose up 30 deg, flying along the nose: the heading climbs at 30 deg.
    v = vehicle_from_odometry(odom([0, 0, 0], 0.0, (10.0, 0.0, 0.0), pitch_deg=30.0), 'map')
    np.testing.assert_allclose(v.heading, [math.cos(math.pi / 6), 0, 0.5], atol=1e-12)
    # Sideslip: a body y velocity at yaw 90 deg flies along -x.
    v = vehicle_from_odometry(odom([0, 0, 0], 90.0, (0.0, 5.0, 0.0)), 'map')
    np.testing.assert_allclose(v.heading, [-1, 0, 0], atol=1e-12)
    # A twist whose child frame is frame_id itself is already in frame_id.
    v = vehicle_from_odometry(odom([0, 0, 0], 90.0, (3.0, 4.0, 0.0), child='map'), 'map')
    np.testing.assert_allclose(v.heading, [0.6, 0.8, 0], atol=1e-12)


def test_below_half_a_metre_per_second_the_heading_is_the_nose():
    v = vehicle_from_odometry(odom([0, 0, 0], 45.0, (0.0, 0.4, 0.0)), 'map')
    assert not v.from_velocity
    np.testing.assert_allclose(v.heading, [math.sqrt(0.5), math.sqrt(0.5), 0], atol=1e-12)


@pytest.mark.parametrize('edit, field', [
    (lambda m: setattr(m.header, 'frame_id', 'odom'), 'header.frame_id'),
    (lambda m: setattr(m.pose.pose.position, 'y', math.nan), 'pose.pose.position'),
    (lambda m: setattr(m.pose.pose.orientation, 'w', math.inf), 'pose.pose.orientation'),
    (lambda m: [setattr(m.pose.pose.orientation, c, 0.0) for c in 'xyzw'],
     'pose.pose.orientation'),
    (lambda m: setattr(m.twist.twist.linear, 'z', math.nan), 'twist.twist.linear'),
    (lambda m: setattr(m.twist.twist.angular, 'x', math.nan), 'twist.twist.angular'),
])
def test_a_bad_odom_is_refused_naming_the_field(edit, field):
    msg = odom([10, 10, 50])
    edit(msg)
    with pytest.raises(InputError, match=f'^odom {field.replace(".", "[.]")}: '):
        vehicle_from_odometry(msg, 'map')


def state(**changes):
    return InputState.from_parameters({**PARAMETER_DEFAULTS, **scenario_params(), **changes})


def test_an_odom_outside_the_bounds_or_on_a_threat_is_refused():
    s = accept(state(), 'threats', pointcloud2_from_threats(
        SCENARIO.threats.positions, SCENARIO.threats.intensities, 'map', Time()))
    with pytest.raises(InputError, match='odom pose.pose.position: .* is outside bounds'):
        accept(s, 'odom', odom([150, 10, 50]))
    on = np.float32(SCENARIO.threats.positions[0]).astype(float)
    with pytest.raises(InputError, match='odom pose.pose.position: .* is on threat 0'):
        accept(s, 'odom', odom(on))
    assert accept(s, 'odom', odom([10, 10, 50])).vehicle is not None


def test_a_cloud_carries_velocities_and_a_still_one_none():
    vel = np.arange(60, dtype=float).reshape(20, 3) - 30.0
    msg = pointcloud2_from_threats(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   'map', Time(sec=3), vel)
    pos, f, v = moving_threats_from_pointcloud2(msg, 'map')
    assert np.array_equal(v, vel) and len(pos) == 20 and msg.point_step == 28
    assert np.array_equal(threats_from_pointcloud2(msg, 'map')[0], pos)
    still = pointcloud2_from_threats(pos, f, 'map', Time())
    assert moving_threats_from_pointcloud2(still, 'map')[2] is None
    s = accept(state(), 'threats', msg)
    assert np.array_equal(s.velocities, vel) and s.threats_stamp_ns == 3 * 10**9
    assert accept(s, 'threats', still).velocities is None


def test_a_nan_velocity_or_a_partial_one_is_refused_naming_the_field():
    vel = np.zeros((20, 3))
    vel[4, 1] = math.nan
    msg = pointcloud2_from_threats(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   'map', Time(), vel)
    with pytest.raises(InputError, match="field 'vy' has 1 non-finite values .*index 4"):
        accept(state(), 'threats', msg)
    msg.fields = [f for f in msg.fields if f.name != 'vz']
    with pytest.raises(InputError, match=r"velocity field\(s\) \['vx', 'vy'\] without \['vz'\]"):
        moving_threats_from_pointcloud2(msg, 'map')


def tracked(s, position, now_ns, yaw=0.0):
    return FlightTracker.took(accept(s, 'odom', odom(position, yaw)), 'odom', now_ns)


class _Request:
    def __init__(self, seq, vehicle):
        self.seq, self.vehicle, self.goal = seq, vehicle, SCENARIO.goal


def test_the_first_odom_replans_the_next_track_and_off_track_replans():
    s = accept(state(), 'threats', pointcloud2_from_threats(
        SCENARIO.threats.positions, SCENARIO.threats.intensities, 'map', Time()))
    tracker, t = FlightTracker(), 10**12
    s = tracked(s, [10, 10, 60], t)
    assert tracker.trigger(s, t) == 'first odom'
    assert tracker.request_fields(s, t) == {'vehicle': s.vehicle}
    tracker.requested(_Request(5, s.vehicle))
    assert tracker.trigger(s, t + 2 * 10**9) is None      # a plan from the vehicle is due
    line = np.array([[10.0, 10, 60], [90, 10, 60], [100, 100, 61.772443772814455]])
    tracker.planned(_Request(5, s.vehicle), line)
    tracker.answered(5)
    s = tracked(s, [30, 11, 60], t + 3 * 10**9)
    assert tracker.trigger(s, t + 3 * 10**9) is None       # on track: tracks
    fields = tracker.request_fields(s, t + 3 * 10**9 + 10**8)
    # In flight: 20 m along, plus 0.1 s at 20 m/s since the odom.
    assert fields['s_now'] == pytest.approx(22.0, abs=1e-9)
    assert np.array_equal(fields['flown'], line)
    # A new goal is replanned in flight too (as fly does): the committed stretch first.
    regoal = accept(s, 'goal_pose', pose([90, 90, 50]))
    assert tracker.request_fields(regoal, t + 3 * 10**9)['s_now'] == pytest.approx(20.0)
    far = tracked(s, [30, 10 + ODOM_DRIFT_M + 1, 60], t + 4 * 10**9)
    assert tracker.trigger(far, t + 4 * 10**9) == 'off track by 6 m'
    assert tracker.request_fields(far, t + 4 * 10**9) == {'vehicle': far.vehicle}
    # Its plan failed: still off track, but no second replan within a second of the first.
    tracker.answered(5)
    assert tracker.trigger(far, t + 4 * 10**9 + 9 * 10**8) is None
    assert tracker.trigger(far, t + 5 * 10**9) == 'off track by 6 m'
    # Odometry that stopped on the trajectory: the vehicle is taken to fly it on; near the
    # goal the trajectory stands.
    fields = tracker.request_fields(s, t + 5 * 10**9)
    assert fields['s_now'] == pytest.approx(60.0, abs=1e-9)
    assert tracker.request_fields(s, t + 9 * 10**9) is None   # 140 m of 170.6 m along
    near = tracked(s, [98, 90, 61.5], t + 8 * 10**9)
    assert tracker.request_fields(near, t + 8 * 10**9) is None
    assert 'flown' in tracker.request_fields(accept(near, 'goal_pose', pose([50, 90, 50])),
                                             t + 8 * 10**9)
    # Stale odometry off any trajectory flown is no start: plan from start.
    assert tracker.request_fields(far, t + 5 * 10**9 + 1) == {}
    assert FlightTracker().request_fields(s, t + 4 * 10**9 + 1) == {}
    assert FlightTracker().request_fields(s, t + 4 * 10**9) == {'vehicle': s.vehicle}


def test_refusals_are_counted_and_said_once_per_kind_of_reason():
    tracker = FlightTracker()
    said = [tracker.refused(r) for r in (
        "odom header.frame_id: 'odom' is not frame_id 'map'",
        'odom pose.pose.position: not finite: [nan, 1.0, 2.0]',
        'odom pose.pose.position: not finite: [3.0, nan, 2.5]',
        "odom header.frame_id: 'odom' is not frame_id 'map'")]
    assert said == [True, True, False, False] and tracker.odom_rejected == 4


def test_a_moving_cloud_far_from_the_node_clock_is_refused():
    msg = pointcloud2_from_threats(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   'map', Time(sec=1), np.ones((20, 3)))
    s = accept(state(), 'threats', msg)
    with pytest.raises(InputError, match='PointCloud2 header.stamp: .* from the node clock'):
        FlightTracker.took(s, 'threats', time.time_ns())
    assert FlightTracker.took(s, 'threats', 10**9 + 5 * 10**9) is s


def test_getplan_through_moving_threats_plans_in_time():
    vel = np.zeros((20, 3))
    vel[[2, 7]] = [[4.0, -3.0, 0.0], [0.0, 6.0, 1.0]]
    cloud_ns = 1_000 * 10**9
    msg = pointcloud2_from_threats(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   'map', ns_to_stamp(cloud_ns), vel)
    s = accept(state(), 'threats', msg)
    request = GetPlan.Request(start=pose(SCENARIO.start),
                              goal=pose(SCENARIO.goal, stamp=ns_to_stamp(cloud_ns + 2 * 10**9)))
    path, reason = plan_on_request(s, request)
    assert reason == ''
    t0 = stamp_to_ns(path.header.stamp)
    assert t0 == cloud_ns + 2 * 10**9
    times = np.array([stamp_to_ns(p.header.stamp) - t0 for p in path.poses]) * 1e-9
    pos, f, v = moving_threats_from_pointcloud2(msg, 'map')
    timeline = ThreatTimeline(s.threats, v, t0=-2.0)
    from threat_planner.core.flight.replan import plan_in_time
    again = plan_in_time(timeline, SCENARIO.start, SCENARIO.goal, s.settings.box,
                         s.settings.config, s.settings.config.speed_mps)
    assert np.array_equal(path_from_msg(path), again.points)
    assert timed_path_cost(path_from_msg(path), times, timeline, 0.5).J == pytest.approx(
        again.cost.J, rel=1e-9)
