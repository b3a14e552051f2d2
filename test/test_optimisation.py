"""Direct J minimisation within the box and the angle limits."""

import numpy as np
import pytest

from threat_planner.core.cost import path_cost
from threat_planner.core.optimisation import angle_constraints, minimise_cost
from threat_planner.core.smoothing import check_angles, resample
from threat_planner.core.threats import Box, ThreatField


def test_angle_constraint_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 10, (7, 3))
    g, jac = angle_constraints(pts, 30.0, 45.0)
    num = np.zeros_like(jac)
    for j in range(jac.shape[1]):
        d = np.zeros(jac.shape[1])
        d[j] = 1e-6
        up = pts.copy()
        up[1:-1] += d.reshape(-1, 3)
        dn = pts.copy()
        dn[1:-1] -= d.reshape(-1, 3)
        num[:, j] = (angle_constraints(up, 30, 45)[0] - angle_constraints(dn, 30, 45)[0]) / 2e-6
    assert np.max(np.abs(num - jac)) < 1e-5 * max(1.0, np.max(np.abs(jac)))
    assert g.shape == (2 * 6 - 1,)


@pytest.fixture
def problem():
    threats = ThreatField.from_arrays([[50.0, 50.0, 50.0], [30.0, 60.0, 40.0]], [2e5, 1e5])
    box = Box.from_corners([0, 0, 0], [100, 100, 100])
    start, goal = np.array([0.0, 0.0, 50.0]), np.array([100.0, 100.0, 50.0])
    return threats, box, start, goal


def test_minimisation_lowers_j_and_keeps_box_and_limits(problem):
    threats, box, start, goal = problem
    x0 = resample(np.vstack([start, [60.0, 40.0, 55.0], goal]), 20)
    res = minimise_cost(x0, threats, 0.5, box, max_pitch_deg=20.0, max_turn_deg=30.0)
    j0 = path_cost(x0, threats.positions, threats.intensities, 0.5).J
    j1 = path_cost(res.points, threats.positions, threats.intensities, 0.5).J
    assert j1 < 0.9 * j0
    assert np.all(res.points >= box.lo - 1e-9) and np.all(res.points <= box.hi + 1e-9)
    assert check_angles(res.points, 20.0, 30.0).feasible
    assert np.allclose(res.points[[0, -1]], x0[[0, -1]])


def test_box_binds_when_the_threat_fills_it(problem):
    threats, box, start, goal = problem
    small = Box.from_corners([0, 0, 45], [100, 100, 55])
    x0 = resample(np.vstack([start, [60.0, 40.0, 50.0], goal]), 16)
    inside = minimise_cost(x0, threats, 0.8, small, 90.0, 180.0)
    free = minimise_cost(x0, threats, 0.8, None, 90.0, 180.0)
    assert np.all(inside.points[:, 2] <= 55 + 1e-9)
    j_in = path_cost(inside.points, threats.positions, threats.intensities, 0.8).J
    j_free = path_cost(free.points, threats.positions, threats.intensities, 0.8).J
    assert j_free <= j_in
