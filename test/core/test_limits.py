"""Physical flight limits: the metrics, the constraints and their Jacobians."""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from threat_planner.core.optimise.limit_kernels import LimitTerm
from threat_planner.core.optimise.limits import (check_limits, climb_angles, constraint_jacobian,
                                                 constraint_values, constraint_values_jacobian,
                                                 constraint_vjp, FlightLimits, turn_radii)

ALL_ON = FlightLimits(20.0, 30.0, 15.0, 0.0)


@given(st.floats(0.5, 500.0), st.floats(1.0, 170.0), st.integers(3, 40),
       st.floats(-math.pi, math.pi), st.floats(-1.4, 1.4))
@settings(max_examples=60, deadline=None)
def test_turn_radius_of_points_on_a_circle(radius, arc_deg, n, yaw, tilt):
    """Points dphi apart on a circle of radius R, in any plane, give R cos(dphi / 2) (twice
    that for three points: both segments are end ones, each the corner's in full)."""
    phi = np.radians(np.linspace(0.0, arc_deg, n))
    local = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(n)], axis=1)
    cy, sy, ct, st_ = math.cos(yaw), math.sin(yaw), math.cos(tilt), math.sin(tilt)
    rot = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, ct, -st_], [0, st_, ct]])
    pts = local @ rot.T + np.array([3.0, -7.0, 11.0])
    dphi = math.radians(arc_deg) / (n - 1)
    whole = 2.0 if n == 3 else 1.0
    np.testing.assert_allclose(turn_radii(pts), whole * radius * math.cos(dphi / 2),
                               rtol=1e-7)


def test_turn_radius_of_a_sampled_circle_tends_to_its_radius():
    radii = []
    for n in (5, 17, 65, 257):
        phi = np.linspace(0.0, math.pi / 2, n)
        radii.append(turn_radii(np.stack([10 * np.cos(phi), 10 * np.sin(phi), 0 * phi], 1))[0])
    assert np.all(np.diff(radii) > 0) and 10.0 - radii[-1] < 1e-4


def test_turn_radius_straight_is_infinite_and_hairpin_zero():
    line = np.array([[0, 0, 0], [1, 1, 1], [3, 3, 3.0]])
    assert np.all(np.isinf(turn_radii(line)))
    back = np.array([[0, 0, 0], [2, 0, 0], [1, 0, 0.0]])
    assert turn_radii(back)[0] == 0.0
    # A repeated vertex is skipped: the fillet is between the distinct neighbours' legs.
    rep = np.array([[1, 0, 0], [0, 1, 0], [0, 1, 0], [-1, 0, 0.0]])
    np.testing.assert_allclose(turn_radii(rep), [math.sqrt(2)])


def test_turn_radius_of_right_angle_corners():
    """A 90 deg corner: share / tan(45 deg), the share all of an end leg, half of another."""
    pts = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0.0]])
    np.testing.assert_allclose(turn_radii(pts), [4.0])
    pts = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0.0], [8, 4, 0.0]])
    np.testing.assert_allclose(turn_radii(pts), [2.0, 2.0])


def test_a_sharp_turn_beside_a_short_segment_is_a_tight_radius():
    """154 deg after a 0.95 m segment (a plan on uniform20_1 had one): the circle through
    the three points is 10.0 m, the fillet that fits is 0.22 m."""
    turn = math.radians(154.3)
    pts = np.array([[0, 0, 0], [0.95, 0, 0],
                    [0.95 + 9.53 * math.cos(turn), 9.53 * math.sin(turn), 0.0],
                    [-20.0, 9.53 * math.sin(turn), 0.0]])
    a, b = pts[1] - pts[0], pts[2] - pts[1]
    circle = (np.linalg.norm(a) * np.linalg.norm(b) * np.linalg.norm(a + b)
              / (2 * np.linalg.norm(np.cross(a, b))))
    assert circle > 9.9
    np.testing.assert_allclose(turn_radii(pts)[0], 0.95 / math.tan(turn / 2))
    assert not check_limits(pts, FlightLimits(90.0, 90.0, 10.0), 0.0).feasible


@given(st.integers(0, 10_000), st.integers(2, 12))
@settings(max_examples=60, deadline=None)
def test_arcs_of_the_least_radius_fit_the_segments(seed, n):
    """With R the path's least radius, the arcs of radius R at every corner (tangent length
    R tan(theta / 2)) fit: two on a segment never overlap, one stays on an end segment."""
    pts = _random_path(seed, n)
    r = float(turn_radii(pts).min())
    d = np.diff(pts, axis=0)
    seg = np.linalg.norm(d, axis=1)
    theta = np.arctan2(np.linalg.norm(np.cross(d[:-1], d[1:]), axis=1),
                       np.einsum('ik,ik->i', d[:-1], d[1:]))
    tangent = np.concatenate([[0.0], r * np.tan(theta / 2), [0.0]])
    assert np.all(tangent[:-1] + tangent[1:] <= seg * (1 + 1e-9))
    # At the tightest corner the arc uses all of a share: half a segment, or an end one.
    k = int(np.argmin(turn_radii(pts)))
    share = np.where((np.arange(n) == 0) | (np.arange(n) == n - 1), seg, seg / 2)
    assert tangent[k + 1] == pytest.approx(min(share[k], share[k + 1]), rel=1e-9)


@pytest.mark.parametrize('dz, horizontal, expected', [
    (1.0, 1.0, 45.0), (-1.0, 1.0, -45.0), (math.sqrt(3), 1.0, 60.0), (5.0, 0.0, 90.0),
    (0.0, 7.0, 0.0)])
def test_climb_angle_of_known_segments(dz, horizontal, expected):
    # The horizontal length split over x and y: the angle only sees its norm.
    pts = np.array([[1.0, 2.0, 3.0],
                    [1.0 + 0.6 * horizontal, 2.0 + 0.8 * horizontal, 3.0 + dz]])
    np.testing.assert_allclose(climb_angles(pts), [expected], atol=1e-12)


def test_check_reports_the_worst_violation():
    pts = np.array([[0, 0, 0], [10, 0, 10], [10, 10, 12.0], [20, 10, 12.0]])  # 45 deg climb
    check = check_limits(pts, FlightLimits(20.0, 30.0, 5.0, 0.0), 0.0)
    assert not check.feasible
    np.testing.assert_allclose(check.violations['climb_deg'], 25.0)
    assert check.climb_deg == pytest.approx(45.0)
    assert check.worst == 'climb_deg'
    ok = check_limits(pts, FlightLimits(), 0.0)
    assert ok.feasible and ok.worst is None and ok.violations == {}


def test_altitude_applies_to_interior_vertices_only():
    pts = np.array([[0, 0, 0.0], [10, 0, 3.0], [20, 0, 0.0]])
    check = check_limits(pts, FlightLimits(min_altitude_m=5.0), 0.0)
    assert check.violations == pytest.approx({'altitude_m': 2.0})
    assert check_limits(pts, FlightLimits(min_altitude_m=3.0), 0.0).feasible


def _random_path(seed, n):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(0.0, 3.0, (n + 1, 3)) + [4.0, 1.0, 0.5], axis=0)


@pytest.mark.parametrize('limits', [ALL_ON, FlightLimits(10.0, 90.0, 0.0, 0.0),
                                    FlightLimits(90.0, 5.0, 0.0, 0.0),
                                    FlightLimits(90.0, 90.0, 40.0, 0.0)])
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_constraint_jacobian_matches_finite_differences(limits, seed):
    pts = _random_path(seed, 7)
    jac = constraint_jacobian(pts, limits)
    num = np.zeros_like(jac)
    for v in range(len(pts)):
        for k in range(3):
            up, dn = pts.copy(), pts.copy()
            h = 1e-6 * max(1.0, abs(pts[v, k]))
            up[v, k] += h
            dn[v, k] -= h
            diff = constraint_values(up, limits) - constraint_values(dn, limits)
            num[:, v, k] = diff / (2 * h)
    scale = np.abs(num).max()
    np.testing.assert_allclose(jac, num, atol=1e-6 * scale)
    weights = np.random.default_rng(seed).normal(size=len(jac))
    np.testing.assert_allclose(constraint_vjp(pts, limits, weights)[1],
                               np.einsum('m,mvk->vk', weights, jac), atol=1e-12 * scale * 50)


@given(st.integers(0, 10_000), st.integers(2, 12))
@settings(max_examples=40, deadline=None)
def test_constraints_agree_with_the_metrics(seed, n):
    """g >= 0 exactly where the measured climb, dive and radius are within the limits."""
    pts = _random_path(seed, n)
    g = constraint_values(pts, ALL_ON)
    ang = climb_angles(pts)
    rad = turn_radii(pts)
    np.testing.assert_array_equal(g[:n] >= 0, ang <= 20.0 + 1e-9)
    np.testing.assert_array_equal(g[n:2 * n] >= 0, -ang <= 30.0 + 1e-9)
    close = np.abs(rad - 15.0) < 1e-9
    both_sides = (g[2 * n:].reshape(2, n - 1) >= 0).all(axis=0)
    np.testing.assert_array_equal(both_sides[~close], (rad >= 15.0)[~close])


@given(st.integers(0, 10_000), st.integers(2, 30), st.floats(0.1, 100.0))
@settings(max_examples=40, deadline=None)
def test_compiled_penalty_is_the_phr_term_of_the_numpy_constraints(seed, n, mu):
    """LimitTerm: the same g, and value and gradient of sum(s^2 - lam^2) / (2 mu)."""
    pts = _random_path(seed, n)
    lam = np.random.default_rng(seed).uniform(0.0, 2.0, len(constraint_values(pts, ALL_ON)))
    term = LimitTerm(ALL_ON, len(pts))
    g = constraint_values(pts, ALL_ON)
    np.testing.assert_allclose(term.values(pts), g, rtol=1e-12, atol=1e-12)
    s = np.maximum(0.0, lam - mu * g)
    value, grad = term.penalty(pts, lam, mu)
    assert value == pytest.approx((s @ s - lam @ lam) / (2.0 * mu), rel=1e-10, abs=1e-12)
    np.testing.assert_allclose(grad, -constraint_vjp(pts, ALL_ON, s)[1], rtol=1e-9,
                               atol=1e-9 * max(1.0, float(np.abs(grad).max())))


def test_a_vertical_segment_is_not_a_stationary_point_of_the_climb_constraint():
    """Straight up breaks a 20 deg climb limit; g must still point the way out."""
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 10.0], [10.0, 10.0, 10.0]])
    jac = constraint_jacobian(pts, FlightLimits(20.0, 90.0, 0.0, 0.0))
    assert constraint_values(pts, FlightLimits(20.0, 90.0, 0.0, 0.0))[0] < 0
    # Moving the top vertex horizontally (towards the goal) raises g: sin(20 deg) / 10 m.
    slope = jac[0, 1, :2] @ np.array([1.0, 1.0]) / math.sqrt(2.0)
    assert slope == pytest.approx(math.sin(math.radians(20.0)) / 10.0)


@given(st.integers(0, 10_000), st.integers(1, 30),
       st.sampled_from([ALL_ON, FlightLimits(10.0, 90.0, 0.0, 0.0),
                        FlightLimits(90.0, 5.0, 25.0, 0.0)]),
       st.sampled_from(['none', 'repeat', 'vertical']))
@settings(max_examples=60, deadline=None)
def test_compiled_jacobian_is_the_numpy_one(seed, n, limits, degenerate):
    """LimitTerm.values_jacobian: the rows and dense Jacobian of constraint_values_jacobian,
    also through a repeated vertex (a zero-length segment) and a vertical segment."""
    pts = _random_path(seed, n)
    if degenerate == 'repeat' and n >= 2:
        pts[1] = pts[0]
    if degenerate == 'vertical' and n >= 2:
        pts[1, :2] = pts[0, :2]
    g, jac = constraint_values_jacobian(pts, limits)
    cg, cjac = LimitTerm(limits, len(pts)).values_jacobian(pts)
    np.testing.assert_allclose(cg, g, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(cjac, jac, rtol=1e-9, atol=1e-12)
