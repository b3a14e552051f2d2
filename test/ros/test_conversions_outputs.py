"""Tests of threat_planner.ros.conversions' outputs (Path, markers, plan_info) and stamps."""

import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Path
import numpy as np
import pytest
from visualization_msgs.msg import Marker, MarkerArray

from conversion_samples import _threats, FRAME, RNG_SEED, STAMP
from threat_planner.errors import InputError
from threat_planner.ros import conversions as conv


def _rotate(q, v):
    """Rotate vector v by unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q
    u = np.array([x, y, z])
    v = np.asarray(v, dtype=float)
    return v + 2.0 * w * np.cross(u, v) + 2.0 * np.cross(u, np.cross(u, v))


def _quat(pose_stamped):
    o = pose_stamped.pose.orientation
    return np.array([o.x, o.y, o.z, o.w])


# -------------------------------------------------------------------- paths


def _directions(points):
    seg = np.diff(points, axis=0)
    return seg / np.linalg.norm(seg, axis=1, keepdims=True)


def test_path_along_x_has_identity_orientation():
    points = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [3.0, 0.0, 5.0]])
    msg = conv.path_to_msg(points, FRAME, STAMP)
    assert isinstance(msg, Path) and msg.header.frame_id == FRAME
    assert len(msg.poses) == 3
    for pose in msg.poses:
        np.testing.assert_allclose(_quat(pose), [0.0, 0.0, 0.0, 1.0], atol=1e-12)
        assert pose.header.frame_id == FRAME and pose.header.stamp == STAMP
    np.testing.assert_array_equal(conv.path_from_msg(msg), points)


def test_path_along_y_has_yaw_90():
    msg = conv.path_to_msg([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]], FRAME, STAMP)
    half = math.sqrt(0.5)
    for pose in msg.poses:
        np.testing.assert_allclose(_quat(pose), [0.0, 0.0, half, half], atol=1e-12)
        np.testing.assert_allclose(_rotate(_quat(pose), [1, 0, 0]), [0, 1, 0], atol=1e-12)


def test_path_climbing_45_deg_is_negative_pitch_and_nose_follows_segment():
    msg = conv.path_to_msg([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0]], FRAME, STAMP)
    q = _quat(msg.poses[0])
    # REP-103: nose up is a negative rotation about +y.
    np.testing.assert_allclose(q, [0.0, -math.sin(math.pi / 8), 0.0, math.cos(math.pi / 8)],
                               atol=1e-12)
    np.testing.assert_allclose(_rotate(q, [1, 0, 0]), [math.sqrt(0.5), 0, math.sqrt(0.5)],
                               atol=1e-12)


def test_path_nose_follows_every_segment_and_y_axis_stays_level():
    rng = np.random.default_rng(RNG_SEED)
    points = np.cumsum(rng.normal(size=(40, 3)) * [10.0, 10.0, 4.0], axis=0)
    msg = conv.path_to_msg(points, FRAME, STAMP)
    dirs = _directions(points)
    expected = np.vstack([dirs, dirs[-1:]])
    for pose, direction in zip(msg.poses, expected):
        q = _quat(pose)
        assert np.linalg.norm(q) == pytest.approx(1.0)
        np.testing.assert_allclose(_rotate(q, [1, 0, 0]), direction, atol=1e-12)
        # No roll: the body y axis stays horizontal.
        assert abs(_rotate(q, [0, 1, 0])[2]) < 1e-12
    np.testing.assert_allclose(conv.path_from_msg(msg), points)


def test_path_degenerate_segments_reuse_previous_direction():
    points = np.array([[0, 0, 0], [0, 0, 0],  # leading duplicate: takes the next heading
                       [0, 1, 0], [0, 1, 0], [0, 1, 0],  # repeated waypoint
                       [0, 1, 2]], dtype=float)
    msg = conv.path_to_msg(points, FRAME, STAMP)
    noses = np.array([_rotate(_quat(p), [1, 0, 0]) for p in msg.poses])
    expected = [[0, 1, 0], [0, 1, 0], [0, 1, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]]
    np.testing.assert_allclose(noses, expected, atol=1e-12)


def test_path_single_point_empty_and_bad_input():
    single = conv.path_to_msg([[1.0, 2.0, 3.0]], FRAME, STAMP)
    np.testing.assert_array_equal(_quat(single.poses[0]), [0, 0, 0, 1])
    empty = conv.path_to_msg(np.empty((0, 3)), FRAME, STAMP)
    assert empty.poses == [] and conv.path_from_msg(empty).shape == (0, 3)
    with pytest.raises(InputError, match=r'shape \(n, 3\)'):
        conv.path_to_msg(np.zeros((4, 2)), FRAME, STAMP)
    with pytest.raises(InputError, match='1 non-finite points'):
        conv.path_to_msg([[0, 0, 0], [1, math.nan, 0]], FRAME, STAMP)


def test_path_poses_are_stamped_with_their_times_to_the_nanosecond():
    from threat_planner.core.trajectory import point_times
    points = np.array([[0.0, 0.0, 5.0], [30.0, 40.0, 5.0], [30.0, 40.0, 17.0]])
    t0 = Time(sec=7, nanosec=999_999_900)
    msg = conv.path_to_msg(points, FRAME, t0, point_times(points, 10.0))
    assert msg.header.stamp == t0
    ns = [conv.stamp_to_ns(p.header.stamp) for p in msg.poses]
    # 50 m then 12 m at 10 m/s: 0, 5 and 6.2 s after t0, the nanoseconds carried over
    assert ns == [7_999_999_900, 12_999_999_900, 14_199_999_900]
    assert conv.path_to_msg(points, FRAME, t0).poses[2].header.stamp == t0


def test_path_times_must_be_one_finite_non_negative_value_per_point():
    points = np.zeros((3, 3))
    with pytest.raises(InputError, match=r'path times: expected 3 \(one per point\), got 2'):
        conv.path_to_msg(points, FRAME, STAMP, [0.0, 1.0])
    for bad in ([0.0, math.nan, 1.0], [0.0, -1.0, 1.0]):
        with pytest.raises(InputError, match='path times: must be finite and >= 0'):
            conv.path_to_msg(points, FRAME, STAMP, bad)


# ------------------------------------------------------------------- markers


def _network(n_threats):
    positions, intensities = _threats(n=n_threats)
    vertices = np.vstack([positions, [[0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]]])
    delaunay_edges = np.array([[0, 1], [1, 2], [2, n_threats + 3]])
    nodes = np.array([[1.0, 1.0, 1.0], [5.0, 5.0, 5.0], [9.0, 1.0, 4.0]])
    network_edges = np.array([[0, 1], [1, 2]])
    return dict(threat_positions=positions, intensities=intensities, vertices=vertices,
                delaunay_edges=delaunay_edges, nodes=nodes, network_edges=network_edges,
                initial_path=nodes, path=np.array([[1.0, 1.0, 1.0], [9.0, 1.0, 4.0]]),
                frame_id=FRAME, stamp=STAMP)


def test_network_markers_small_threat_count_uses_scaled_spheres():
    args = _network(5)
    array = conv.network_markers(**args)
    assert isinstance(array, MarkerArray)
    markers = array.markers
    assert markers[0].action == Marker.DELETEALL
    assert len(markers) == 1 + 5 + 5
    by_ns = {}
    for m in markers[1:]:
        by_ns.setdefault(m.ns, []).append(m)
        assert m.action == Marker.ADD and m.header.frame_id == FRAME
        assert m.header.stamp == STAMP
    assert sorted(by_ns) == ['delaunay', 'initial_path', 'network', 'nodes', 'path', 'threats']
    spheres = by_ns['threats']
    assert [m.type for m in spheres] == [Marker.SPHERE] * 5
    assert sorted(m.id for m in spheres) == list(range(5))
    diameters = np.array([m.scale.x for m in spheres])
    strongest = int(np.argmax(args['intensities']))
    assert diameters[strongest] == pytest.approx(4.0)
    assert diameters.min() >= 0.8 - 1e-12
    np.testing.assert_allclose(diameters, 4.0 * np.maximum(
        args['intensities'] / args['intensities'].max(), 0.2))
    centres = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                        for m in spheres])
    np.testing.assert_array_equal(centres, args['threat_positions'])

    (mesh,) = by_ns['delaunay']
    assert mesh.type == Marker.LINE_LIST and len(mesh.points) == 6
    last = mesh.points[-1]
    assert (last.x, last.y, last.z) == (0.0, 0.0, 100.0)
    (nodes,) = by_ns['nodes']
    assert nodes.type == Marker.SPHERE_LIST and len(nodes.points) == 3
    (net,) = by_ns['network']
    assert net.type == Marker.LINE_LIST and len(net.points) == 4
    assert (net.points[1].x, net.points[2].x) == (5.0, 5.0)
    for ns, n in (('initial_path', 3), ('path', 2)):
        (strip,) = by_ns[ns]
        assert strip.type == Marker.LINE_STRIP and len(strip.points) == n


def test_network_markers_many_threats_use_one_sphere_list():
    args = _network(conv.SPHERES_PER_THREAT_MAX + 1)
    markers = conv.network_markers(**args).markers
    threats = [m for m in markers if m.ns == 'threats']
    assert len(threats) == 1 and threats[0].type == Marker.SPHERE_LIST
    assert len(threats[0].points) == len(threats[0].colors) == conv.SPHERES_PER_THREAT_MAX + 1
    assert len(markers) == 1 + 1 + 5


def test_network_markers_skip_missing_parts_and_reject_bad_edges():
    args = _network(3)
    args.update(initial_path=None, path=np.empty((0, 3)), network_edges=np.empty((0, 2)))
    markers = conv.network_markers(**args).markers
    assert markers[0].action == Marker.DELETEALL
    assert {m.ns for m in markers[1:]} == {'threats', 'delaunay', 'nodes'}
    args = _network(3)
    args['network_edges'] = np.array([[0, 1], [2, 3]])
    with pytest.raises(InputError, match=r'network_edges row 1 \[2, 3\] indexes outside 0..2'):
        conv.network_markers(**args)
    args = _network(3)
    args['intensities'] = args['intensities'][:2]
    with pytest.raises(InputError, match='intensities must have shape'):
        conv.network_markers(**args)


# --------------------------------------------------------------- diagnostics


def test_plan_info_round_trip():
    values = {'cost': 0.1 + 0.2, 'threat_cost': np.float64(1.0 / 3.0), 'n_nodes': 42,
              'n_edges': np.int64(7), 'converged': True, 'note': 'fine',
              'length_m': 1234.5678901234567}
    msg = conv.plan_info_msg('WARN', 'slow', values, STAMP)
    assert isinstance(msg, DiagnosticArray) and msg.header.stamp == STAMP
    (status,) = msg.status
    assert status.name == 'threat_planner: plan' and status.hardware_id == 'threat_planner'
    assert status.level == DiagnosticStatus.WARN and status.message == 'slow'
    back = conv.plan_info_values(msg)
    assert list(back) == list(values)
    assert float(back['cost']) == 0.1 + 0.2
    assert float(back['threat_cost']) == 1.0 / 3.0
    assert float(back['length_m']) == 1234.5678901234567
    assert back['n_nodes'] == '42' and back['n_edges'] == '7'
    assert back['converged'] == 'True' and back['note'] == 'fine'
    levels = {s: conv.plan_info_msg(s, '', {}, STAMP, hardware_id='uav1').status[0]
              for s in ('OK', 'ERROR')}
    assert levels['OK'].level == DiagnosticStatus.OK
    assert levels['ERROR'].level == DiagnosticStatus.ERROR
    assert levels['OK'].hardware_id == 'uav1'
    with pytest.raises(InputError, match="'FATAL'"):
        conv.plan_info_msg('FATAL', '', {}, STAMP)
    with pytest.raises(InputError, match='no status'):
        conv.plan_info_values(DiagnosticArray())


# --------------------------------------------------------------------- time


def test_stamp_ns_round_trip():
    assert conv.stamp_to_ns(Time(sec=3, nanosec=7)) == 3_000_000_007
    for ns in (0, 1, 999_999_999, 1_000_000_000, 1_717_000_000_123_456_789):
        stamp = conv.ns_to_stamp(ns)
        assert isinstance(stamp, Time) and 0 <= stamp.nanosec < 1_000_000_000
        assert conv.stamp_to_ns(stamp) == ns
    with pytest.raises(InputError, match='-5 ns'):
        conv.ns_to_stamp(-5)
    with pytest.raises(InputError, match='int32'):
        conv.ns_to_stamp(2**31 * 1_000_000_000)
