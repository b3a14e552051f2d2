"""A path in time: times are length over speed, headings are unit tangents, attitudes agree."""

import math
from pathlib import Path

import numpy as np
import pytest

from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.core.trajectory import (eta, heading_quaternions, headings, point_times,
                                            quaternion_yaw_pitch, quaternions, segment_lengths,
                                            yaw_pitch)
from threat_planner.errors import InputError


def _polyline(rng, m):
    pts = rng.normal(scale=30.0, size=(m, 3))
    # Repeated points (zero-length segments), as a resampled or clipped path may hold.
    for k in rng.integers(1, m, size=m // 5):
        pts[k] = pts[k - 1]
    return pts


@pytest.mark.parametrize('seed', range(20))
def test_times_are_the_length_flown_so_far_over_the_speed(seed):
    """Brute force: each point's time is the sum of math.dist over the segments before it,
    over the speed, from t0."""
    rng = np.random.default_rng(seed)
    pts = _polyline(rng, int(rng.integers(2, 60)))
    speed, t0 = float(rng.uniform(0.5, 80.0)), float(rng.uniform(-100.0, 100.0))
    t = point_times(pts, speed, t0)
    for k in range(len(pts)):
        flown = sum(math.dist(pts[i], pts[i + 1]) for i in range(k))
        assert t[k] == pytest.approx(t0 + flown / speed, rel=1e-12, abs=1e-12)
    assert np.all(np.diff(t) >= 0.0)
    assert eta(pts, speed) == pytest.approx(t[-1] - t0, rel=1e-12)
    assert segment_lengths(pts) == pytest.approx([math.dist(a, b) for a, b in
                                                  zip(pts[:-1], pts[1:])], rel=1e-12)


def test_twice_the_speed_takes_half_the_time():
    pts = np.array([[0.0, 0.0, 0.0], [30.0, 40.0, 0.0], [30.0, 40.0, 120.0]])
    assert point_times(pts, 10.0).tolist() == [0.0, 5.0, 17.0]
    assert point_times(pts, 20.0).tolist() == [0.0, 2.5, 8.5]
    assert point_times(pts[:1], 10.0, 3.0).tolist() == [3.0]
    assert point_times(np.zeros((0, 3)), 10.0).shape == (0,)
    assert eta(pts[:1], 10.0) == 0.0


@pytest.mark.parametrize('speed', [0.0, -1.0, float('nan'), float('inf'), '20'])
def test_a_speed_that_is_not_finite_and_positive_is_refused_naming_it(speed):
    with pytest.raises(InputError, match='^speed_mps: must'):
        point_times(np.zeros((2, 3)), speed)


@pytest.mark.parametrize('points, what', [
    (np.zeros((3, 2)), r'points: expected shape \(M, 3\), got \[3, 2\]'),
    ([[0.0, 0.0, float('nan')]], 'points: must be finite'),
])
def test_bad_points_are_refused(points, what):
    with pytest.raises(InputError, match=what):
        point_times(points, 10.0)
    with pytest.raises(InputError, match=what):
        headings(points)


@pytest.mark.parametrize('seed', range(20))
def test_headings_are_unit_tangents_of_the_segment_ahead(seed):
    rng = np.random.default_rng(100 + seed)
    pts = _polyline(rng, int(rng.integers(2, 60)))
    h = headings(pts)
    assert h.shape == pts.shape
    assert np.allclose(np.linalg.norm(h, axis=1), 1.0, rtol=0, atol=1e-12)
    seg = np.diff(pts, axis=0)
    usable = np.linalg.norm(seg, axis=1) > 1e-9
    for k in range(len(seg)):
        # Along its own segment where it has one; else the nearest usable one before it
        # (the first usable one after it for leading repeats).
        j = k if usable[k] else (max((i for i in range(k) if usable[i]), default=None)
                                 if usable[:k].any() else int(np.argmax(usable)))
        assert np.allclose(h[k], seg[j] / np.linalg.norm(seg[j]), atol=1e-12)
    assert np.array_equal(h[-1], h[-2])   # the last point keeps the last segment's


def test_zero_length_segments_inherit_a_neighbour_s_heading():
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 5.0, 0.0],
                    [0.0, 5.0, 7.0]])
    # Leading repeat: the first usable segment's; inner repeat: the one before it.
    assert headings(pts).tolist() == [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0],
                                      [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    # No direction at all: the identity attitude's, +x.
    assert headings(np.ones((3, 3))).tolist() == [[1.0, 0.0, 0.0]] * 3
    assert headings(np.ones((1, 3))).tolist() == [[1.0, 0.0, 0.0]]


def test_yaw_is_about_z_and_pitch_positive_nose_up():
    h = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 1.0],
                  [1.0, 1.0, -math.sqrt(2.0)]])
    yp = yaw_pitch(h)
    assert yp == pytest.approx(np.array([[0.0, 0.0], [math.pi / 2, 0.0], [math.pi, 0.0],
                                         [0.0, math.pi / 4], [math.pi / 4, -math.pi / 4]]))


def _rotate(q, v):
    """v turned by the unit quaternion q = (x, y, z, w), by the Hamilton product."""
    x, y, z, w = q
    u = np.array([x, y, z])
    return 2.0 * np.dot(u, v) * u + (w * w - np.dot(u, u)) * v + 2.0 * w * np.cross(u, v)


@pytest.mark.parametrize('seed', range(10))
def test_quaternions_turn_the_nose_along_the_heading_and_read_back(seed):
    rng = np.random.default_rng(200 + seed)
    pts = _polyline(rng, 30)
    h = headings(pts)
    yp = yaw_pitch(h)
    q = quaternions(yp)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    for qk, hk in zip(q, h):
        assert np.allclose(_rotate(qk, np.array([1.0, 0.0, 0.0])), hk, atol=1e-12)
        # Zero roll: the body y axis (left wing) stays horizontal.
        assert abs(_rotate(qk, np.array([0.0, 1.0, 0.0]))[2]) < 1e-12
    assert np.allclose(quaternion_yaw_pitch(q), yp, atol=1e-9)
    assert np.array_equal(heading_quaternions(pts), q)


def test_a_climb_is_a_negative_rotation_about_y_as_rep_103_has_it():
    q = quaternions([[0.0, math.pi / 2]])[0]      # straight up
    assert q == pytest.approx([0.0, -math.sqrt(0.5), 0.0, math.sqrt(0.5)])
    assert quaternions([[0.0, 0.0]]).tolist() == [[0.0, 0.0, 0.0, 1.0]]


@pytest.mark.parametrize('speed', [0.0, -5.0, float('nan'), float('inf'), 1000.5])
def test_the_speed_setting_refuses_what_no_vehicle_flies(speed):
    with pytest.raises(InputError, match=r'^speed_mps: must be finite and > 0 and <= 1000, '
                                         r'got '):
        PlannerConfig(speed_mps=speed).validated()
    assert PlannerConfig(speed_mps=1000.0).validated().speed_mps == 1000.0


def test_configs_that_differ_only_in_speed_plan_alike():
    a, b = PlannerConfig(), PlannerConfig(speed_mps=7.5)
    assert a != b and hash(a) != hash(b)      # still distinct settings
    assert a.plans_like(b) and b.plans_like(a)
    assert not a.plans_like(PlannerConfig(w=0.6, speed_mps=7.5))


# ---- the plan is timed, never shaped, by the speed -------------------------------------

DATA = Path(__file__).resolve().parents[1] / 'data'


@pytest.fixture(scope='module')
def uniform():
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    return sc, plan(sc.threats, sc.start, sc.goal, sc.box)


@pytest.mark.parametrize('method', ['best', 'paper'])
def test_the_speed_changes_no_plan_bit_for_bit(uniform, method):
    sc, _ = uniform
    base = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(method=method))
    slow = plan(sc.threats, sc.start, sc.goal, sc.box,
                PlannerConfig(method=method, speed_mps=3.5))
    assert np.array_equal(base.path, slow.path)
    assert np.array_equal(base.initial_path, slow.initial_path)
    assert base.cost == slow.cost and base.node_sequence == slow.node_sequence
    assert slow.speed_mps == 3.5 and base.speed_mps == 20.0
    assert slow.eta_s == pytest.approx(base.eta_s * 20.0 / 3.5, rel=1e-12)


def test_the_summary_times_the_path_points(uniform):
    _, r = uniform
    s = r.summary()
    assert s['speed_mps'] == 20.0 and len(s['t']) == len(s['path'])
    assert s['t'] == point_times(r.path, 20.0).tolist() and s['t'][0] == 0.0
    assert s['eta_s'] == s['t'][-1] == r.eta_s


def test_a_new_speed_alone_keeps_a_warm_replan_warm(uniform):
    sc, first = uniform
    start = first.path[2]      # flown two segments along the last path
    warm = plan(sc.threats, start, sc.goal, sc.box, PlannerConfig(speed_mps=9.0),
                warm_start=first)
    assert warm.warm_note == 'warm' and warm.speed_mps == 9.0
    other = plan(sc.threats, start, sc.goal, sc.box, PlannerConfig(w=0.6), warm_start=first)
    assert other.warm_note == 'cold: settings changed'
