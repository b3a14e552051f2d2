"""Issue 28: a replan after a move of the threats no user could mean keeps its J.

A planner in a loop replans every new threat picture from its last plan (``warm_start``,
as the node does). Moving every threat of a random field by at most 1 um must then leave J
within 0.1 % of the plan's or lower (issue 28's target): the replan keeps the previous
plan's basin (core/methods/warm.py's tie rule) and refines the previous path as it is.
The fields: 12-35 threats at the bundled density, start and goal on opposite box edges,
flight limits on (the defaults), w 0.2 / 0.5 / 0.8, and the straight line climbing at most
20 deg (nearer the 30 deg limit no seed meets the slopes at the screening's 8 segments,
more plans know no lead over another basin and replan cold, and cold plans there still
jump: bench/results/perturbation.md).

On the starting code of issue 28 (3609ebb) the replan was cold wherever the limits bound
and no second basin had been refined under them (and from the previous path resampled
evenly where it was warm): over seeds 0-399 (n 12 / 20 / 35, w 0.5 / 0.8, a third of the
pairs, 800 replans) 24 came out more than 0.1 % higher, seed 361 (n 35, w 0.8) +51 % and
seed 298 (n 20, w 0.8) +7.4 %; both are explicit examples here and run every time, and so does
this test's own seed 84 (n 20, w 0.5: +0.7 % where no lead was known and the replan went
cold). With the change every one of those replans is warm and none is higher (7 are 0.1
to 0.6 % lower: the replan refines the previous path further).
"""

from functools import lru_cache

from hypothesis import example, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from cpu_plans import corner_switchback
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.world.threats import Box, ThreatField

#: Largest relative rise of J allowed from the plan to its replan.
TOLERANCE = 1e-3
#: Largest move of a threat [m].
MOVE = 1e-6


def field(seed: int, n: int):
    """Threats, start, goal and box of one random field (seeded)."""
    rng = np.random.default_rng([28, seed, n])
    side = 100.0 * (n / 20.0) ** (1.0 / 3.0)
    threats = ThreatField.from_arrays(rng.uniform(0.05 * side, 0.95 * side, (n, 3)),
                                      rng.uniform(1e5, 4e5, n) * rng.uniform(0.3, 3.0, n))
    z = rng.uniform(0.0, side)
    rise = np.tan(np.radians(20.0)) * np.sqrt(2.0) * side
    s = np.array([0.0, 0.0, z])
    t = np.array([side, side, np.clip(z + rng.uniform(-rise, rise), 0.0, side)])
    return threats, s, t, Box.from_corners([0.0] * 3, [side] * 3)


@settings(max_examples=12, derandomize=True, database=None, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), n=st.sampled_from([12, 20, 35]),
       w=st.sampled_from([0.2, 0.5, 0.8]))
@example(seed=361, n=35, w=0.8)
@example(seed=298, n=20, w=0.8)
@example(seed=84, n=20, w=0.5)
def test_a_replan_after_a_micrometre_move_keeps_its_j(seed, n, w):
    threats, s, t, box = field(seed, n)
    cfg = PlannerConfig(w=w)
    first = plan(threats, s, t, box, cfg)
    d = np.random.default_rng(seed).normal(size=threats.positions.shape)
    d *= MOVE * np.random.default_rng(seed + 1).uniform(0.0, 1.0, (n, 1)) / np.linalg.norm(
        d, axis=1)[:, None]
    moved = ThreatField.from_arrays(threats.positions + d, threats.intensities)
    again = plan(moved, s, t, box, cfg, warm_start=first)
    assert first.feasible and again.feasible
    assert again.cost.J <= (1.0 + TOLERANCE) * first.cost.J, (
        first.cost.J, again.cost.J, first.seed, again.seed, again.warm_note)


def _bundled(name):
    from pathlib import Path
    from threat_planner.core.inputs.scenario import load_scenario
    return load_scenario(Path(__file__).resolve().parents[1] / 'data' / f'{name}.yaml')


def test_a_replan_from_the_same_start_refines_the_previous_path_as_it_is():
    """Resampled evenly, the previous path's corners broke the turn radius (w 0.8)."""
    from threat_planner.core.methods.warm import warm_path
    from threat_planner.core.optimise.limits import check_limits, FlightLimits
    from threat_planner.core.optimise.smoothing import resample
    sc = _bundled('uniform20_0')
    cfg = PlannerConfig(w=0.8)
    first = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    moved = ThreatField.from_arrays(sc.threats.positions + 1e-3, sc.threats.intensities)
    path, note = warm_path(first, moved, sc.start, sc.goal, sc.box, cfg)
    assert note == 'warm' and np.array_equal(path, first.path)
    limits, floor = FlightLimits.of(cfg), float(sc.box.lo[2])
    assert check_limits(path, limits, floor).feasible
    assert not check_limits(resample(first.path, cfg.n_points), limits, floor).feasible


@pytest.mark.parametrize('lead, move, warm', [(1e-3, 0.05, True), (1e-3, 0.5, False),
                                              (0.0, 1e-3, True), (0.0, 0.05, False)])
def test_the_lead_a_warm_replan_needs_grows_with_the_move(lead, move, warm):
    """In the 173 m diagonal: a 0.1 % lead holds against a 5 cm move (0.06 % needed), not
    a 0.5 m one (0.6 %); up to 1.7 mm the previous basin is kept with no lead known."""
    import dataclasses
    from threat_planner.core.methods.warm import warm_path
    sc = _bundled('weak20_0')
    cfg = PlannerConfig(w=0.5)
    first = dataclasses.replace(plan(sc.threats, sc.start, sc.goal, sc.box, cfg),
                                basin_margin=lead)
    moved = ThreatField.from_arrays(sc.threats.positions + move / np.sqrt(3.0),
                                    sc.threats.intensities)
    _, note = warm_path(first, moved, sc.start, sc.goal, sc.box, cfg)
    assert (note == 'warm') == warm
    assert warm or note.startswith('cold: basins within 0.1 %' if lead else 'cold: the flight')


def test_the_winner_converges_never_above_its_unconverged_j(monkeypatch):
    """Its rounds again at FINAL_EVEN from its own path (refining.converge): never higher."""
    from threat_planner.core.methods import best
    sc = _bundled('uniform20_0')
    # The converge alone: the limited basins added after it converge their own.
    monkeypatch.setattr(best, 'LIMITED_BASINS_MAX_THREATS', 0)
    j = {}
    for label in ('converged', 'plain'):
        if label == 'plain':
            monkeypatch.setattr(best, 'converge', lambda p, cand: cand)
        j[label] = [plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w)).cost.J
                    for w in (0.2, 0.5)]
    assert all(a <= b for a, b in zip(j['converged'], j['plain']))
    assert j['converged'][1] < (1.0 - 1e-4) * j['plain'][1]    # 155.02 -> 154.93 measured


@pytest.mark.parametrize('name', ['uniform20_0', 'uniform20_1'])
def test_the_winner_converges_until_its_last_rounds_stop_gaining(name, monkeypatch):
    """At w 0.8 one run of the last rounds ended at 144.9655 / 175.0233, where its L-BFGS
    stalled; a fresh run from that end went lower, twice more (144.9627 / 175.0213). The
    runs now repeat while they gain (refining.CONVERGE_GAIN): the plan is >= 5e-6 lower."""
    from threat_planner.core.methods import best, refining
    sc = _bundled(name)
    monkeypatch.setattr(best, 'LIMITED_BASINS_MAX_THREATS', 0)    # the converge alone
    j = {}
    for runs in (1, refining.CONVERGE_RUNS):
        monkeypatch.setattr(refining, 'CONVERGE_RUNS', runs)
        j[runs] = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.8)).cost.J
    assert j[max(j)] < (1.0 - 5e-6) * j[1]


@pytest.mark.parametrize('seed', [6, 7, 8])
def test_cold_plans_of_one_basin_end_at_its_minimum(seed):
    """uniform20_0 at w 0.8, every threat moved 1 um (bench perturbation's fields, cold
    plans): the rounds stopped on a small gain anywhere along the slope the spacing term
    holds them on, J 145.07 unmoved and 145.27 / 145.30 / 145.08 moved (+0.14 % and
    +0.16 % for seeds 6 and 7 on 7985131). Converged (refining.converge) they end at the
    minima SLSQP finds from those ends: the unmoved plan and seed 8 at 144.96, seeds 6
    and 7 at 144.77, 0.13 % lower (the basin choice between the two stays open)."""
    sc = _bundled('uniform20_0')
    cfg = PlannerConfig(w=0.8)
    given = plan(sc.threats, sc.start, sc.goal, sc.box, cfg).cost.J
    d = np.random.default_rng(seed).normal(size=sc.threats.positions.shape)
    d *= MOVE / np.linalg.norm(d, axis=1)[:, None]
    moved = ThreatField.from_arrays(sc.threats.positions + d, sc.threats.intensities)
    j = plan(moved, sc.start, sc.goal, sc.box, cfg).cost.J
    assert j <= (1.0 + TOLERANCE) * given, (given, j)


def _perturbation_case(name: str):
    """Return bench perturbation's module, the case's index (its seeds) and the case."""
    import importlib
    import sys
    from pathlib import Path
    root = str(Path(__file__).resolve().parents[2])
    if root not in sys.path:
        sys.path.insert(0, root)
    bench = importlib.import_module('bench.suites.perturbation')
    k, case = next((k, c) for k, c in enumerate(bench.cases()) if c[0] == name)
    return bench, k, case


@lru_cache(maxsize=None)
def _unmoved_plan(name: str):
    """The plan of a bench perturbation case as it is (planned once for every test)."""
    _, _, (_, threats, s, t, box, w) = _perturbation_case(name)
    return plan(threats, s, t, box, PlannerConfig(w=w))


def _unmoved_and_moved(name: str, seed: int, size: float):
    """The case's plan and its plan with every threat moved by `size` [m] (bench seed)."""
    bench, k, (_, threats, s, t, box, w) = _perturbation_case(name)
    moved = bench.nudged(threats, bench.SEEDS * k + seed, size)
    return _unmoved_plan(name), plan(moved, s, t, box, PlannerConfig(w=w))


def test_a_finest_level_gone_astray_is_refined_again_subdivided():
    """n20 seed 1 w 0.8 of bench perturbation's random fields, every threat moved 1 nm
    (its seed 1): the winner's finest level ended at J 452 against 392 at 20 segments,
    and its rounds again from that answer broke a limit, so the plan was 452, 13 % above
    the unmoved plan's 399.1 (on a2fc7e7). Refined again with every level subdivided
    (best._polish) it ends at 395.8."""
    given, moved = _unmoved_and_moved('n20 seed 1 w 0.8', 1, 1e-9)
    assert given.feasible and moved.feasible
    assert moved.cost.J <= (1.0 + TOLERANCE) * given.cost.J, (given.cost.J, moved.cost.J)


def test_a_polished_finest_level_is_rerun_at_the_first_penalty_too():
    """The same field moved 1 um (the bench's seed 1 of that size): the finest level ended
    at 1601 against 388 at 20 segments; its rounds again at WARM_PENALTY ended 401.4 and
    converged to 401.1, 0.50 % above the unmoved 399.1 (on 95affb9). At PENALTY_START they
    end 399.4, converged 399.2; each rerun is converged before the lowest is kept (kept
    unconverged, the lower rerun converged higher: the unmoved plan ended at 399.2).
    Without BLAS in the arithmetic (core/_vector.py) the unmoved plan is 395.97."""
    given = _unmoved_plan('n20 seed 1 w 0.8')
    assert given.feasible and given.cost.J < 399.15, given.cost.J


def test_every_basin_is_settled_before_a_rescue_is_weighed_against_it():
    """The same field moved 1 mm (the bench's seed 1 of that size): its one feasible basin
    (the straight line, slopes held) went astray at J 1,692, a stalled basin rescued to
    408.2 beat it unpolished, and the plan converged to 407.3, 2.9 % above the unmoved
    395.8 (on 15dd261). Every refined candidate is polished before the basins are
    compared: the astray one ends at 395.7 and wins."""
    given, moved = _unmoved_and_moved('n20 seed 1 w 0.8', 1, 1e-3)
    assert given.feasible and moved.feasible
    assert moved.cost.J <= (1.0 + TOLERANCE) * given.cost.J, (given.cost.J, moved.cost.J)


@pytest.mark.parametrize('name, before, after', [
    ('n35 seed 2 w 0.5', 225.57, 213.8), ('n35 seed 1 w 0.8', 404.43, 392.5)])
def test_seeds_tied_at_the_screening_are_refined_too(name, before, after, monkeypatch):
    """Slope-held seeds within basins.SCREEN_TIE (5 %) of the best one's screening J are
    ties at 8 segments, and each is refined as a runner-up. These two fields' winners
    screened 2.0 % and 3.8 % above the best and refine to 213.73 and 392.41; the first two
    basins refined gave 225.57 and 404.43 (on 3992abd, and here without ties)."""
    from threat_planner.core.methods import basins
    _, _, (_, threats, s, t, box, w) = _perturbation_case(name)
    tied = _unmoved_plan(name)
    from threat_planner.core.methods import best
    # The ties alone: without them the limited basins find these winners too.
    monkeypatch.setattr(best, 'LIMITED_BASINS_MAX_THREATS', 0)
    monkeypatch.setattr(basins, 'SCREEN_TIE', 0.0)
    untied = plan(threats, s, t, box, PlannerConfig(w=w))
    assert tied.feasible and untied.feasible
    assert tied.cost.J < after < before < untied.cost.J + 0.01, (tied.cost.J, untied.cost.J)


@pytest.mark.parametrize('name', ['n20 seed 1 w 0.8', 'n120 seed 0 w 0.5'])
def test_the_fields_whose_cold_plans_move_replan_in_a_loop_within_the_target(name):
    """The two cases whose cold plans move most under bench perturbation's moves (up to
    +2.9 % and +0.95 %: the rounds from a finest level started 19 deg over a slope limit
    end chaotically) replanned as the node does, warm from the unmoved plan: all nine
    moves (1 nm, 1 um, 1 mm; the bench's seeds) warm and within 0.1 % of its J or lower
    (measured at most +0.03 % over the 66 cases)."""
    bench, k, (_, threats, s, t, box, w) = _perturbation_case(name)
    given = _unmoved_plan(name)
    for size in bench.MOVES:
        for i in range(bench.SEEDS):
            moved = bench.nudged(threats, bench.SEEDS * k + i, size)
            again = plan(moved, s, t, box, PlannerConfig(w=w), warm_start=given)
            assert again.warm and again.feasible, (size, i, again.warm_note)
            assert again.cost.J <= (1.0 + TOLERANCE) * given.cost.J, (size, i, again.cost.J)


def test_a_warm_replan_without_limits_refines_the_previous_path_itself():
    """n120 seed 0 w 0.8 with the limits off: warm replans ran the box-only levels again
    from the previous path resampled to 10 segments, and under the optimiser's cut-off
    (120 threats x 40 segments) the rounds lower a J without the far threats: up to
    +0.17 % over the previous plan after 1 nm-1 mm moves. Now the finest level alone from
    the path as it is, and never above that start in exact J."""
    from threat_planner.core.inputs.settings import NO_LIMITS
    bench, k, (_, threats, s, t, box, w) = _perturbation_case('n120 seed 0 w 0.8')
    cfg = PlannerConfig(w=w, **NO_LIMITS)
    given = plan(threats, s, t, box, cfg)
    for size in bench.MOVES:
        for i in range(bench.SEEDS):
            moved = bench.nudged(threats, bench.SEEDS * k + i, size)
            again = plan(moved, s, t, box, cfg, warm_start=given)
            assert again.warm and again.cost.J <= (1.0 + 2e-4) * given.cost.J, (
                size, i, again.cost.J / given.cost.J)


def test_the_corner_field_moved_a_micrometre_keeps_its_j():
    """That move held J within 0.1 % on OpenBLAS's SkylakeX kernels (95affb9 to 1cdc140),
    where the same code on its Haswell kernels planned the unmoved field at 395.81, not
    399.14. With the arithmetic the same on every CPU (core/_vector.py) the unmoved plan is
    395.97 and this one 399.22, one of 4 of the case's 9 moved plans above 1.001
    (bench/results/perturbation.md). Since the limited basins (methods/limited_basins.py)
    both end in the same basin again (this test was an expected failure until then)."""
    given, moved = _unmoved_and_moved('n20 seed 1 w 0.8', 1, 1e-6)
    assert given.feasible and moved.feasible
    assert moved.cost.J <= (1.0 + TOLERANCE) * given.cost.J, (given.cost.J, moved.cost.J)


@pytest.mark.xfail(strict=True, reason='since the far field (world/far_field.py) the '
                   'unmoved plan is 408.37 and the moved one 405.42 (+0.72 %); counting every '
                   'threat exactly, 407.30 and 408.06: the cut-off alone had held them together')
def test_equal_breaches_start_the_rounds_from_the_box_only_optimum():
    """n120 seed 0 w 0.8 of bench perturbation's random fields: the runner-up's box-only
    optimum and its seed broke the limits equally (0.866), and rounding chose which the
    rounds started from: 490.4 unmoved, 408.5 with every threat moved 1 nm (on d18d96f).
    With optimisation.START_MARGIN both start from the box-only optimum and end together,
    near 405."""
    given, moved = (r.cost.J for r in _unmoved_and_moved('n120 seed 0 w 0.8', 0, 1e-9))
    assert abs(moved / given - 1.0) <= TOLERANCE and given < 410.0, (given, moved)


@pytest.mark.parametrize('name, w', [('uniform20_1', 0.811), ('uniform20_0', 0.544)])
def test_a_looser_climb_limit_never_plans_higher(name, w):
    """The path planned at max climb c meets every looser limit, so J may only fall as c
    rises. Under the circumradius rule (e12b44a) uniform20_1 at w 0.811 rose +25 % at 24
    deg (a 154 deg turn after a 0.95 m segment) and uniform20_0 at w 0.544 rose 5 times
    (up to +7.8 % at 29 deg); with the fillet rule but the slope screening strict
    (d712ab7), uniform20_1 rose +36 % at 24 deg (its 178 basins ended 0.04-0.33 deg over
    the slopes and ranked last)."""
    sc = _bundled(name)
    js = [plan(sc.threats, sc.start, sc.goal, sc.box,
               PlannerConfig(w=w, max_climb_deg=float(c))).cost.J for c in range(20, 40)]
    rises = [(20 + i + 1, b / a) for i, (a, b) in enumerate(zip(js, js[1:]))
             if b > (1.0 + TOLERANCE) * a]
    assert not rises, rises


def test_rounds_held_by_a_folded_vertex_go_on():
    """The same field with every threat moved 1 nm (the bench's seed 106): a vertex of the
    finest level folded 1.5e-5 m onto the start, six rounds ended at one J and violation
    (437.50, 0.085) and the plan came out at J 1691.3, 4.23x the unmoved 399.4 (3470672).
    Unfolded when a round stalls, it is 452.1 (1.13x: the finest level still lands in
    other places as the threats move by nanometres, bench/results/perturbation.md)."""
    threats, s, t, box = corner_switchback()
    d = np.random.default_rng(106).normal(size=threats.positions.shape)
    d *= 1e-9 / np.linalg.norm(d, axis=1)[:, None]
    moved = ThreatField.from_arrays(threats.positions + d, threats.intensities)
    got = plan(moved, s, t, box, PlannerConfig(w=0.8))
    assert got.feasible and got.cost.J < 500.0, (got.cost.J, got.seed)


def test_a_winner_far_above_its_coarse_answer_is_refined_again_from_it(monkeypatch):
    """python -m bench perturbation's n20 seed 1 w 0.8 (20 threats, start and goal at
    opposite corners of the box): the first vertex folded onto the start, the rounds
    stalled there and the plan came out at J 1216 (its 1 um twins 396 to 3444); run again
    from the coarser level's answer it is 400 (best.UNSETTLED)."""
    from threat_planner.core.methods import best
    threats, s, t, box = corner_switchback()
    again = plan(threats, s, t, box, PlannerConfig(w=0.8))
    monkeypatch.setattr(best, 'UNSETTLED', np.inf)
    once = plan(threats, s, t, box, PlannerConfig(w=0.8))
    assert again.feasible and again.cost.J <= once.cost.J
    assert again.cost.J < 420.0, (again.cost.J, once.cost.J)
