"""Plans under the physical flight limits, their report, and warm starts."""

import json
from pathlib import Path

import numpy as np
import pytest

from threat_planner.core.inputs.config import PlannerConfig as Config
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.inputs.settings import PHYSICAL_LIMITS
from threat_planner.core.methods.best import repair
from threat_planner.core.methods.problem import Candidate, Clock, Problem
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.optimise.smoothing import check_angles
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.world.threats import Box, ThreatField
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


BUNDLED = ['uniform20_0', 'uniform20_1', 'weak20_0', 'strongweak_0', 'clustered_0',
           'ground_0', 'coplanar_0']


def test_the_limits_are_on_by_default_and_are_the_yardsticks():
    cfg = PlannerConfig()
    assert FlightLimits.of(cfg).as_dict() == {**PHYSICAL_LIMITS, 'min_altitude_m': 0.0}
    assert FlightLimits.of(cfg).any_constraint


@pytest.mark.parametrize('name', BUNDLED)
def test_default_plans_on_every_bundled_scenario_are_feasible(name):
    sc = load_scenario(DATA + f'{name}.yaml')
    for w in (0.2, 0.8):
        r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w))
        check = check_limits(r.path, FlightLimits(**PHYSICAL_LIMITS), float(sc.box.lo[2]))
        assert r.feasible and check.feasible, (w, check.violations)
        assert np.all(r.path >= sc.box.lo - 1e-9) and np.all(r.path <= sc.box.hi + 1e-9)


@pytest.mark.parametrize('n_points', [20, 80])
def test_default_limits_hold_at_any_resolution_where_they_bind(n_points):
    """uniform20_0 at w = 0.5: the limit-free optimum breaks the limits; both fixes hold."""
    sc = load_scenario(DATA + 'uniform20_0.yaml')
    r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5, n_points=n_points))
    check = check_limits(r.path, FlightLimits(**PHYSICAL_LIMITS), 0.0)
    assert len(r.path) == n_points + 1 and check.feasible
    assert check.min_turn_radius_m >= 10.0 * (1 - 1e-6)
    assert max(check.climb_deg, check.dive_deg) <= 30.0 + 1e-6


def test_repair_blends_towards_the_line_until_every_limit_holds():
    """An infeasible zig-zag comes back as the feasible blend nearest it, J exact."""
    sc = load_scenario(DATA + 'weak20_0.yaml')
    cfg = Config(w=0.5, n_points=20)
    p = Problem(threats=sc.threats, s=sc.start, t=sc.goal, box=sc.box, config=cfg,
                network=None, edge_j=None, clock=Clock())
    line = np.linspace(sc.start, sc.goal, 21)
    inner = (np.arange(21) % 20 > 0)[:, None]
    zig = line + np.outer((-1.0) ** np.arange(21), [0.0, 0.0, 8.0]) * inner
    zig = sc.box.clip(zig)
    bad = Candidate(seq=[], initial=zig, smoothed=None, smoothed_cost=None, final=zig,
                    k=float('nan'), steps=0, converged=True, cost=p.cost(zig),
                    angles=check_angles(zig, 90.0, 180.0), limit_check=p.check(zig))
    assert not bad.limit_check.feasible
    fixed = repair(p, bad)
    assert fixed.limit_check.feasible and check_limits(fixed.final, p.limits, 0.0).feasible
    assert fixed.cost.J == p.cost(fixed.final).J
    # The largest feasible blend: a little further towards the zig-zag breaks a limit.
    a = float(fixed.seed.split('(')[1].split()[0])
    assert 0.0 < a < 1.0
    assert not p.check(line + min(1.0, a * 1.01 + 1e-3) * (zig - line)).feasible


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


def test_crowded_fields_always_replan_cold():
    """Their basins shift with any move: a warm replan there came out 33 % above cold."""
    sc = load_scenario(DATA + 'big300_0.yaml')
    cfg = PlannerConfig(w=0.5, max_climb_deg=90.0, max_dive_deg=90.0, min_turn_radius_m=0.0)
    first = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    again = plan(sc.threats, first.path[1], sc.goal, sc.box, cfg, warm_start=first)
    assert not again.warm and again.warm_note.startswith('cold: crowded field')


def _bench_tools():
    """The bench's cases (bench/toolkit/cases.py), for its exact warm-replan move."""
    import importlib
    import sys
    root = str(Path(__file__).resolve().parents[2])
    if root not in sys.path:
        sys.path.insert(0, root)
    return importlib.import_module('bench.toolkit.cases')


def test_a_warm_start_that_breaks_a_limit_refines_at_full_resolution_no_worse_than_cold():
    """The speed bench's uniform20_0 at w 0.5: the previous path from the new start,
    resampled, breaks a limit; the warm replan still ends at the cold plan's J or below,
    within the spread of the neighbouring minima both end in (converged from each end:
    140.849 and 140.840, 6e-5 apart; the plans before refining.converge, 141.18 and 141.23)."""
    from threat_planner.core.methods.warm import warm_path
    sc = load_scenario(DATA + 'uniform20_0.yaml')
    cfg = PlannerConfig(w=0.5)
    first = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    moved = _bench_tools().moved_threats(sc.threats, sc.box.diagonal)
    start = first.path[3]
    path, note = warm_path(first, moved, start, sc.goal, sc.box, cfg)
    assert note == 'warm'
    assert not check_limits(path, FlightLimits.of(cfg), float(sc.box.lo[2])).feasible
    warm = plan(moved, start, sc.goal, sc.box, cfg, warm_start=first)
    cold = plan(moved, start, sc.goal, sc.box, cfg)
    assert warm.warm and warm.feasible
    assert warm.cost.J <= cold.cost.J * (1 + 1e-4)
