"""Plans under the physical flight limits, their report, and warm starts."""

import json

import numpy as np
import pytest

from threat_planner.core.limits import check_limits, FlightLimits
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.scenario import load_scenario
from threat_planner.core.threats import Box, ThreatField
from threat_planner.errors import InputError

DATA = 'test/data/'
LIMITS = dict(max_climb_deg=20.0, max_dive_deg=30.0, min_turn_radius_m=15.0)


@pytest.mark.parametrize('n_points', [20, 80])
def test_plans_at_any_resolution_meet_the_same_limits(n_points):
    sc = load_scenario(DATA + 'weak20_0.yaml')
    r = plan(sc.threats, sc.start, sc.goal, sc.box,
             PlannerConfig(w=0.5, n_points=n_points, **LIMITS))
    check = check_limits(r.path, FlightLimits(**LIMITS), float(sc.box.lo[2]))
    assert r.feasible and check.feasible
    assert check.climb_deg <= 20.0 + 1e-6 and check.dive_deg <= 30.0 + 1e-6
    assert check.min_turn_radius_m >= 15.0 * (1 - 1e-6)
    summary = json.loads(json.dumps(r.summary()))
    assert summary['limits']['min_turn_radius_m'] == 15.0
    assert summary['path_limits']['climb_deg'] == pytest.approx(check.climb_deg)
    assert summary['feasible'] is True and summary['worst_violation'] is None


def test_impossible_climb_is_reported_infeasible_with_the_violation():
    """A 10 m wide shaft, 100 m up: a 20 deg climb needs turns tighter than 15 m."""
    box = Box.from_corners([0, 0, 0], [10, 10, 100])
    threats = ThreatField.from_arrays([[5.0, 5.0, 50.0]], [1.0])
    r = plan(threats, [0, 0, 1], [10, 10, 99], box, PlannerConfig(w=0.5, **LIMITS))
    assert not r.feasible
    s = r.summary()
    assert s['feasible'] is False and s['worst_violation'] is not None
    assert s['path_limits']['violations'][s['worst_violation']] > 0


def test_minimum_altitude_above_box_height_is_refused():
    sc = load_scenario(DATA + 'weak20_0.yaml')
    with pytest.raises(InputError, match='min_altitude_m'):
        plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(min_altitude_m=500.0))


@pytest.mark.parametrize('name, w', [('uniform20_0', 0.5), ('weak20_0', 0.2)])
def test_warm_replan_after_small_moves_is_no_worse_than_cold(name, w):
    sc = load_scenario(DATA + f'{name}.yaml')
    cfg = PlannerConfig(w=w)
    first = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    rng = np.random.default_rng(3)
    diag = sc.box.diagonal
    moved = ThreatField.from_arrays(
        sc.threats.positions + rng.uniform(-1, 1, sc.threats.positions.shape) * 0.005 * diag,
        sc.threats.intensities)
    start = first.path[3]      # flown three segments along the last path
    warm = plan(moved, start, sc.goal, sc.box, cfg, warm_start=first)
    cold = plan(moved, start, sc.goal, sc.box, cfg)
    assert not cold.warm
    if warm.warm:
        assert warm.cost.J <= cold.cost.J * (1 + 1e-6)
        assert 'warm_ms' in warm.timings_ms
    else:
        assert warm.warm_note.startswith('cold')
        assert warm.cost.J == pytest.approx(cold.cost.J)


def test_warm_start_refused_when_the_goal_moves():
    sc = load_scenario(DATA + 'weak20_0.yaml')
    first = plan(sc.threats, sc.start, sc.goal, sc.box)
    again = plan(sc.threats, sc.start, sc.goal - [0, 0, 5.0], sc.box, warm_start=first)
    assert not again.warm and again.warm_note == 'cold: goal moved'
