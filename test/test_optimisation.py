"""Direct J minimisation within the box and the physical flight limits."""

import numpy as np
import pytest

from threat_planner.core.cost import path_cost
from threat_planner.core.limits import check_limits, FlightLimits
from threat_planner.core.optimisation import minimise_cost
from threat_planner.core.smoothing import resample
from threat_planner.core.threats import Box, ThreatField


@pytest.fixture
def problem():
    threats = ThreatField.from_arrays([[50.0, 50.0, 50.0], [30.0, 60.0, 40.0]], [2e5, 1e5])
    box = Box.from_corners([0, 0, 0], [100, 100, 100])
    start, goal = np.array([0.0, 0.0, 50.0]), np.array([100.0, 100.0, 50.0])
    return threats, box, start, goal


def test_minimisation_lowers_j_and_keeps_box_and_limits(problem):
    threats, box, start, goal = problem
    x0 = resample(np.vstack([start, [60.0, 40.0, 65.0], goal]), 20)
    limits = FlightLimits(8.0, 8.0, 20.0, 0.0)
    res = minimise_cost(x0, threats, 0.5, box, limits)
    j0 = path_cost(x0, threats.positions, threats.intensities, 0.5).J
    j1 = path_cost(res.points, threats.positions, threats.intensities, 0.5).J
    assert j1 < 0.9 * j0
    assert np.all(res.points >= box.lo - 1e-9) and np.all(res.points <= box.hi + 1e-9)
    assert check_limits(res.points, limits, 0.0).feasible
    assert not check_limits(x0, limits, 0.0).feasible
    assert np.allclose(res.points[[0, -1]], x0[[0, -1]])


def test_minimum_altitude_is_a_bound(problem):
    threats, box, start, goal = problem
    x0 = resample(np.vstack([start, [60.0, 40.0, 20.0], goal]), 16)
    res = minimise_cost(x0, threats, 0.5, box, FlightLimits(min_altitude_m=45.0))
    assert np.all(res.points[1:-1, 2] >= 45.0 - 1e-9)


def test_box_binds_when_the_threat_fills_it(problem):
    threats, box, start, goal = problem
    small = Box.from_corners([0, 0, 45], [100, 100, 55])
    x0 = resample(np.vstack([start, [60.0, 40.0, 50.0], goal]), 16)
    inside = minimise_cost(x0, threats, 0.8, small)
    free = minimise_cost(x0, threats, 0.8, None)
    assert np.all(inside.points[:, 2] <= 55 + 1e-9)
    j_in = path_cost(inside.points, threats.positions, threats.intensities, 0.8).J
    j_free = path_cost(free.points, threats.positions, threats.intensities, 0.8).J
    assert j_free <= j_in


def test_the_fine_level_resumed_from_the_coarse_state_is_the_full_run(problem):
    """stop_before_finest, then resume: the same path as one uninterrupted minimisation."""
    threats, box, start, goal = problem
    x0 = resample(np.vstack([start, [60.0, 40.0, 65.0], goal]), 40)
    limits = FlightLimits(8.0, 8.0, 20.0, 0.0)
    full = minimise_cost(x0, threats, 0.5, box, limits)
    part = minimise_cost(x0, threats, 0.5, box, limits, stop_before_finest=True)
    assert full.constrained and part.state is not None
    assert len(part.points) == 21                       # the 20-segment level's answer
    rest = minimise_cost(x0, threats, 0.5, box, limits, resume=part.state)
    np.testing.assert_array_equal(rest.points, full.points)
