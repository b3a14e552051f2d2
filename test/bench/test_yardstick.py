"""Fast tests of the in-box yardsticks (bench/toolkit/yardstick.py, flight_limits.py)."""

import importlib
import math
from pathlib import Path
import sys

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.world.threats import Box, ThreatField

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
bt = importlib.import_module('bench.toolkit.grid')
fl = importlib.import_module('bench.toolkit.flight_limits')
ys = importlib.import_module('bench.toolkit.yardstick')

W = 0.5


@pytest.fixture(scope='module')
def field():
    """A 20 m box with three threats near the straight line from start to goal."""
    threats = ThreatField.from_arrays([[10.0, 10.5, 10.3], [6.0, 5.0, 9.0], [14.0, 15.0, 11.0]],
                                      [300.0, 150.0, 150.0])
    box = Box.from_corners([0.0, 0.0, 0.0], [20.0, 20.0, 20.0])
    return threats, np.array([0.0, 0.0, 10.0]), np.array([20.0, 20.0, 10.0]), box


@pytest.fixture(scope='module')
def in_box(field):
    threats, start, goal, box = field
    graph = bt.build_grid(threats, start, goal, box, n=7)
    return ys.in_box_yardstick(threats, start, goal, box, W, graph=graph, coarse=8,
                               fine=16), graph


def test_resample_equal_segments_ends_kept():
    p = np.array([[0.0, 0, 0], [3, 0, 0], [3, 4, 0], [3, 4, 12]])
    r = ys.resample(p, 19)
    seg = np.linalg.norm(np.diff(r, axis=0), axis=1)
    np.testing.assert_allclose(seg, 1.0, rtol=1e-12)
    np.testing.assert_array_equal(r[[0, -1]], p[[0, -1]])


def test_grid_routes_first_is_grid_floor_and_routes_differ(field, in_box):
    threats, *_ = field
    graph = in_box[1]
    routes = ys.grid_routes(graph, W, routes=3)
    floor, j_floor, _, _ = bt.grid_floor(graph, threats, W)
    np.testing.assert_array_equal(routes[0], floor)
    assert len({r.tobytes() for r in routes}) == len(routes) >= 2
    costs = [path_cost(r, threats.positions, threats.intensities, W).J for r in routes]
    assert min(costs) == pytest.approx(j_floor, rel=1e-12)


def test_in_box_yardstick_inside_exact_and_better_than_seeds(field, in_box):
    threats, start, goal, box = field
    r, graph = in_box
    path = r['path']
    assert all(box.contains(q) for q in path)
    np.testing.assert_array_equal(path[[0, -1]], [start, goal])
    pos, f = threats.positions, threats.intensities
    assert r['J'] == path_cost(path, pos, f, W).J
    straight = path_cost(np.array([start, goal]), pos, f, W).J
    _, grid_j, _, _ = bt.grid_floor(graph, threats, W)
    assert r['J'] <= straight
    assert r['J'] <= grid_j
    assert r['J'] < 0.99 * min(straight, grid_j)  # the refinement does real work here


def test_turn_radius_of_sampled_circle():
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0.0, 5.0, 9))
    # A circle of radius 7 in a tilted plane, sampled at uneven angles.
    e1 = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    e2 = np.array([-1.0, 1.0, 2.0]) / math.sqrt(6)
    pts = 3.0 + 7.0 * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)
    # From the arcs alone: chords 2 R sin(dt / 2), the turn at a vertex the mean of the
    # arcs beside it, each chord's share half of it (all of an end chord).
    dt = np.diff(t)
    share = 7.0 * np.sin(dt / 2)
    share[[0, -1]] *= 2.0
    expected = np.minimum(share[:-1], share[1:]) / np.tan((dt[:-1] + dt[1:]) / 4)
    np.testing.assert_allclose(fl.turn_radii(pts), expected, rtol=1e-9)
    line = np.outer(np.linspace(0.0, 1.0, 5), [1.0, 2.0, 3.0])
    assert np.all(np.isinf(fl.turn_radii(line)))


def test_climb_and_dive_angles():
    pts = np.array([[0.0, 0, 0], [3, 4, 5], [6, 8, 5], [6, 8 + math.sqrt(3), 4]])
    np.testing.assert_allclose(fl.segment_angles(pts), [45.0, 0.0, -30.0], atol=1e-12)
    got = fl.flight_limits(pts)
    assert got['max_climb_deg'] == pytest.approx(45.0)
    assert got['max_dive_deg'] == pytest.approx(30.0)
    assert fl.check_limits(pts, fl.Limits(45.0, 30.0, 0.0))
    assert not fl.check_limits(pts, fl.Limits(44.9, 30.0, 0.0))
    assert not fl.check_limits(pts, fl.Limits(45.0, 29.9, 0.0))
    assert fl.segment_angles([[0, 0, 0], [0, 0, 1]])[0] == 90.0


def test_check_limits_turn_radius():
    # Quarter circle of radius 10 in 6 equal steps of 15 deg: every fillet is 10 cos 7.5 deg.
    t = np.linspace(0.0, math.pi / 2, 7)
    pts = np.stack([10 * np.cos(t), 10 * np.sin(t), np.zeros(7)], axis=1)
    r = 10 * math.cos(math.radians(7.5))
    assert fl.check_limits(pts, fl.Limits(1.0, 1.0, r))
    assert not fl.check_limits(pts, fl.Limits(1.0, 1.0, r * 1.0001))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_constraints_agree_with_checker_and_jacobian(seed):
    rng = np.random.default_rng(seed)
    p = np.cumsum(rng.uniform(0.5, 2.0, (9, 3)) * [1.0, 1.0, rng.uniform(-0.6, 0.6)], axis=0)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    lim = fl.Limits(30.0, 25.0, float(rng.uniform(0.5, 4.0)))
    cons = fl.LimitConstraints(p[0], p[-1], lim, float(seg.mean()), spacing=10.0)
    z = p[1:-1].ravel()
    g = cons(z)
    spacing_ok = np.all(seg > seg.mean() / 10) and np.all(seg < seg.mean() * 10)
    if spacing_ok and np.all(g >= 0):
        assert fl.check_limits(p, lim)
    jac = cons.jacobian(z)
    fd = np.empty_like(jac)
    for k in range(len(z)):
        e = np.zeros_like(z)
        e[k] = 1e-6
        fd[:, k] = (cons(z + e) - cons(z - e)) / 2e-6
    np.testing.assert_allclose(jac, fd, atol=1e-5 * max(1.0, np.abs(fd).max()))


def test_limited_yardstick_feasible_and_not_below_in_box(field, in_box):
    threats, start, goal, box = field
    r = in_box[0]
    lim = fl.flight_limits(r['path'])
    # Limits the unlimited optimum breaks, so the constraints must bind.
    climb = 0.5 * max(lim['max_climb_deg'], lim['max_dive_deg'], 10.0)
    radius = 2.0 * min(lim['min_turn_radius_m'], 10.0)
    assert not fl.check_limits(r['path'], fl.Limits(climb, climb, radius))
    out = ys.limited_yardstick(threats, start, goal, box, W, climb, climb, radius,
                               n_segments=16, in_box=r, maxiter=150,
                               max_starts=2)
    path = out['path']
    assert out['feasible']
    assert fl.check_limits(path, fl.Limits(climb, climb, radius))
    assert all(box.contains(q) for q in path)
    assert out['J'] == path_cost(path, threats.positions, threats.intensities, W).J
    assert out['J'] >= r['J']
    assert len(path) == 17
