"""The rules of method best that decide warm starts and coarse levels, on made-up cases."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.methods.basins import (basin_lead as _lead,
                                                refined_margin as _refined_margin,
                                                runner_up_lead as _runner_up_lead,
                                                RUNNER_UP_MARGIN)
from threat_planner.core.optimise.optimisation import is_crowded
from threat_planner.core.world.threats import Box

DATA = Path(__file__).resolve().parents[1] / 'data'
BOX = Box(np.zeros(3), np.full(3, 100.0))
PROBLEM = SimpleNamespace(box=BOX)


def _path(bend):
    """A path from (0,0,0) to (100,100,50) bent sideways by `bend` [m] in the middle."""
    t = np.linspace(0.0, 1.0, 9)[:, None]
    p = t * np.array([100.0, 100.0, 50.0])
    p[:, 0] += bend * np.sin(np.pi * t[:, 0])
    return p


def _cand(j, bend, feasible=True):
    return SimpleNamespace(cost=SimpleNamespace(J=j), final=_path(bend),
                           limit_check=SimpleNamespace(feasible=feasible))


def test_lead_is_over_the_next_distinct_basin():
    # 0.5 m apart is the same basin (1 % of the 173 m diagonal is 1.7 m); 20 m is not.
    ranked = [(100.0, _path(0.0)), (100.5, _path(0.5)), (110.0, _path(20.0))]
    assert _lead(PROBLEM, ranked) == pytest.approx(0.10)
    assert _lead(PROBLEM, ranked[:2]) == float('inf')


def test_refined_margin_is_the_screenings_capped_by_a_feasible_distinct_rival():
    best = _cand(100.0, 0.0)
    same = _cand(100.2, 0.4)
    other = _cand(103.0, 25.0)
    # Only the same basin refined: no rival, the screening's lead stands.
    assert _refined_margin(PROBLEM, best, [best, same], 0.5) == 0.5
    # A distinct basin 3 % worse caps the screening's 5 % lead; a smaller one stands.
    assert _refined_margin(PROBLEM, best, [best, same, other], 0.05) == pytest.approx(0.03)
    assert _refined_margin(PROBLEM, best, [best, other], 0.01) == pytest.approx(0.01)
    # An infeasible runner-up is no comparison (it caps nothing) ...
    assert _refined_margin(PROBLEM, best, [best, _cand(90.0, 25.0, False)], 0.05) == 0.05
    # ... and an infeasible best has no lead.
    worst = _cand(100.0, 0.0, feasible=False)
    assert _refined_margin(PROBLEM, worst, [worst, other], 0.05) == 0.0


def test_the_lead_is_the_least_one_known():
    from threat_planner.core.methods.basins import known_lead
    nan, inf = float('nan'), float('inf')
    assert known_lead(0.05, 0.03) == 0.03 and known_lead(0.05, inf) == 0.05
    assert known_lead(nan, 0.87) == 0.87       # a screening that met no slope caps nothing
    assert known_lead(nan, inf) == 0.0         # nothing known: no warm start
    assert known_lead(inf, inf) == inf         # every seed in one basin, none other refined
    assert known_lead(-0.01, inf) == 0.0


@pytest.mark.parametrize('name, crowded', [('big300_0', True), ('uniform20_0', False),
                                           ('weak20_0', False), ('coplanar_0', False)])
def test_crowded_fields_are_those_whose_threat_reach_exceeds_the_spacing(name, crowded):
    sc = load_scenario(DATA / f'{name}.yaml')
    reach = float(np.median(sc.threats.intensities)) ** 0.25
    assert (reach >= sc.threats.typical_spacing(sc.box)) == crowded
    assert is_crowded(sc.threats, sc.box) == crowded


def test_a_runner_up_is_finished_only_if_it_may_win():
    """Same basin stops it at any level; clearly worse only at the last coarse level.

    Close, breaking a limit, or at a coarser level (J far from the final one there) it is
    refined on.
    """
    class Costs(SimpleNamespace):
        def cost(self, points):
            return SimpleNamespace(J=self.j[round(float(points[4, 0] - 50.0), 3)])

    problem = Costs(box=BOX,
                    j={0.0: 100.0, 0.5: 100.2, 20.0: 100.0 * (1 + 2 * RUNNER_UP_MARGIN),
                       30.0: 100.0 * (1 + RUNNER_UP_MARGIN / 2)})
    mine = _path(0.0)
    # best's own basin: no rival, a lead that caps nothing
    assert _runner_up_lead(problem, mine, _path(0.5), True) == float('inf')
    assert _runner_up_lead(problem, mine, _path(0.5), False, last=False) == float('inf')
    assert _runner_up_lead(problem, mine, _path(20.0), True) == pytest.approx(
        2 * RUNNER_UP_MARGIN)
    assert _runner_up_lead(problem, mine, _path(20.0), True, last=False) is None
    assert _runner_up_lead(problem, mine, _path(20.0), False) is None
    assert _runner_up_lead(problem, mine, _path(30.0), True) is None


def test_the_runner_up_gate_compares_level_by_level_and_records_its_verdict():
    """A level best has no answer for goes on; a clearly worse one stops with its lead."""
    from threat_planner.core.methods.basins import runner_up_gate as _runner_up_gate

    class Costs(SimpleNamespace):
        def cost(self, points):
            return SimpleNamespace(J=100.0 + float(np.max(points[:, 0] - points[:, 1])))

        def check(self, points):
            return SimpleNamespace(feasible=True)

    verdict = []
    gate = _runner_up_gate(Costs(box=BOX), (_path(0.0)[::2],), verdict)
    assert gate(_path(20.0)) is False and verdict == []      # no answer of best at 9 points
    assert gate(_path(20.0)[::2]) is True and verdict == [pytest.approx(0.2)]


@pytest.mark.parametrize('name, cut, smooth', [('big300_0', False, False),
                                               ('uniform20_0', True, False),
                                               ('uniform20_0', False, True)])
def test_the_preconditioner_runs_only_on_uncrowded_fields_with_every_threat(
        name, cut, smooth, monkeypatch):
    """Its path-wide steps crossed threat cores on big300_0 and unseen ones under a cut-off."""
    from threat_planner.core.optimise import optimisation
    from threat_planner.core.optimise.limits import FlightLimits
    from threat_planner.core.optimise.smoothing import resample

    seen = []
    real = optimisation.minimise

    def spy(*args, **kwargs):
        seen.append(kwargs['precondition'])
        return real(*args, **kwargs)

    monkeypatch.setattr(optimisation, 'minimise', spy)
    sc = load_scenario(DATA / f'{name}.yaml')
    x0 = resample(np.vstack([sc.start, sc.goal]), 20)
    optimisation.minimise_cost(x0, sc.threats, 0.5, sc.box, FlightLimits(30.0, 30.0, 10.0),
                               cutoff=3.0 * sc.threats.typical_spacing(sc.box) if cut else None)
    assert seen and set(seen) == {smooth}


@pytest.mark.parametrize('name, held_first', [('big300_0', False), ('uniform20_0', True)])
def test_a_crowded_field_refines_the_box_only_ranking_first(name, held_first, monkeypatch):
    """8 segments misrank a crowded field's basins: there the box-only ranking leads."""
    from threat_planner.core.methods import best
    from threat_planner.core.planner import plan, PlannerConfig
    names = []
    real = best.refine
    monkeypatch.setattr(best, 'refine',
                        lambda p, start, seq, name, **k: names.append(name)
                        or real(p, start, seq, name, **k))
    sc = load_scenario(DATA / f'{name}.yaml')
    result = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5))
    assert result.feasible and names
    assert names[0].endswith('(slopes held)') == held_first


def test_a_seed_through_a_threat_never_wins(monkeypatch):
    """strongweak_0's straight line crosses a threat (J inf) yet meets the slopes: with two
    screening rounds it ranked first and was returned as the plan (PlanningError)."""
    from threat_planner.core.methods import basins
    from threat_planner.core.planner import plan, PlannerConfig
    monkeypatch.setattr(basins, 'SLOPE_SCREEN_ROUNDS', 2)
    sc = load_scenario(DATA / 'strongweak_0.yaml')
    result = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5))
    assert np.isfinite(result.cost.J) and result.feasible
    from threat_planner.core.cost.kernels import path_cost
    line = np.vstack([sc.start, sc.goal])
    assert path_cost(line, sc.threats.positions, sc.threats.intensities, 0.5).J == np.inf


def test_the_slope_screening_leaves_out_only_seeds_that_cannot_rank_in_the_first_two(
        monkeypatch):
    """Box-only optima whose J is past the second-best held J: the top two are unchanged."""
    from threat_planner.core.methods import basins, best
    from threat_planner.core.planner import plan, PlannerConfig
    seen = {}
    real = basins.slope_screening

    def spy(p, screened, bounds, cutoff, optimal, tolerance):
        calls = []
        original = basins.minimise_cost
        monkeypatch.setattr(basins, 'minimise_cost',
                            lambda *a, **k: calls.append(1) or original(*a, **k))
        pruned = real(p, screened, bounds, cutoff, optimal, tolerance)
        n_pruned = len(calls)
        full = real(p, screened, bounds, cutoff, set(), tolerance)
        monkeypatch.setattr(basins, 'minimise_cost', original)
        seen.update(pruned=pruned, full=full, runs=(n_pruned, len(calls) - n_pruned))
        return pruned

    monkeypatch.setattr(best, 'slope_screening', spy)
    sc = load_scenario(DATA / 'uniform20_1.yaml')
    plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.2))
    pruned, full = seen['pruned'][0], seen['full'][0]
    assert seen['runs'][0] < seen['runs'][1]
    for a, b in zip(pruned[:2], full[:2]):
        assert a[0] == b[0]
        np.testing.assert_array_equal(a[2], b[2])
    assert seen['pruned'][1] <= seen['full'][1]


def test_a_shortcut_refine_that_ends_infeasible_is_redone_the_long_way(monkeypatch):
    """box_broken skips the box-only run; if that leaves the limits broken, refine again."""
    from threat_planner.core.methods import best
    calls = []

    def fake(p, start, seq, name, box_broken=False, gate=None):
        calls.append(box_broken)
        return SimpleNamespace(final=start, cost=SimpleNamespace(J=100.0),
                               limit_check=SimpleNamespace(feasible=not box_broken))

    monkeypatch.setattr(best, 'refine', fake)
    start = _path(0.0)
    assert best.usable(best._refine(None, start, [], 'x', True)) and calls == [True, False]
    calls.clear()
    best._refine(None, start, [], 'x', False)
    assert calls == [False]


def _rules_problem(name, **limits):
    from threat_planner.core.optimise.limits import FlightLimits
    sc = load_scenario(DATA / f'{name}.yaml')
    lim = FlightLimits(**{'max_climb_deg': 30.0, 'max_dive_deg': 30.0,
                          'min_turn_radius_m': 10.0, **limits})
    return SimpleNamespace(threats=sc.threats, box=sc.box, limits=lim)


def test_crowded_fields_without_limits_count_every_threat_and_others_keep_cut_offs():
    from threat_planner.core.methods.refining import counts_far_threats, optimiser_cutoff
    off = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0}
    crowded_off = _rules_problem('big300_0', **off)
    assert counts_far_threats(crowded_off)
    assert optimiser_cutoff(40, crowded_off) is None          # 12,000 pairs, all counted
    assert optimiser_cutoff(80, crowded_off) is not None      # 24,000: too many
    crowded_on = _rules_problem('big300_0')
    assert not counts_far_threats(crowded_on)
    assert optimiser_cutoff(40, crowded_on) == pytest.approx(
        3.0 * crowded_on.threats.typical_spacing(crowded_on.box))
    sparse_off = _rules_problem('uniform20_0', **off)
    assert not is_crowded(sparse_off.threats, sparse_off.box)
    assert not counts_far_threats(sparse_off)


def test_surface_routes_cost_the_lattice_exactly_up_to_the_pairs_allowed(monkeypatch):
    import threat_planner.core.network.seeds as seeds
    sc = load_scenario(DATA / 'big300_0.yaml')
    radii = []
    real = seeds.segment_costs

    def spy(a, b, threats, radius):
        radii.append(radius)
        return real(a, b, threats, radius)
    monkeypatch.setattr(seeds, 'segment_costs', spy)
    exact = seeds.surface_routes(sc.threats, sc.start, sc.goal, sc.box, 0.5,
                                 dense_pairs=500_000)
    cut = seeds.surface_routes(sc.threats, sc.start, sc.goal, sc.box, 0.5)
    assert radii[0] is None and radii[1] == pytest.approx(
        seeds.CUTOFF_SPACINGS * sc.threats.typical_spacing(sc.box))
    # Each is the least-J route of its own lattice costs: the exact one's J is no higher.
    from threat_planner.core.cost.closed_form import path_cost
    j = [path_cost(r[0], sc.threats.positions, sc.threats.intensities, 0.5).J
         for r in (exact, cut)]
    assert j[0] <= j[1] * (1 + 1e-12)


def test_a_candidate_stalled_short_of_a_limit_gets_rounds_again_and_wins(monkeypatch):
    # A crowded field (python -m bench crowded_fields, seed 6) where, measured, the rounds on
    # the best basin stopped at a 32.6 deg climb against 30 deg and a basin 51 % higher
    # won. Whether they stall there moves with rounding (a 1 nm move of the threats, or
    # another CPU, and they do not), so the stall is made here: the best basin's rounds
    # start at a penalty too weak to enforce anything.
    import threat_planner.core.methods.best as best
    from threat_planner.core.planner import plan, PlannerConfig
    from threat_planner.core.world.threats import ThreatField
    rng = np.random.default_rng([6, 300, 77])
    threats = ThreatField.from_arrays(rng.uniform(50.0, 950.0, (300, 3)),
                                      rng.uniform(1e9, 4e9, 300))
    box = Box.from_corners([0.0] * 3, [1000.0] * 3)
    s, t = np.array([0.0, 0.0, 500.0]), np.array([1000.0, 1000.0, 500.0])
    cfg = PlannerConfig(w=0.8)
    real = best.refine

    def weak(p, start, seq, name, **kw):
        if name.startswith('surface route 0') and not kw.get('warm'):
            kw['penalty'] = 1e-9
        return real(p, start, seq, name, **kw)

    monkeypatch.setattr(best, 'refine', weak)
    # The rescue alone: the limited basins added after it would find a lower basin too.
    monkeypatch.setattr(best, 'LIMITED_BASINS_MAX_THREATS', 0)
    rescued = plan(threats, s, t, box, cfg)
    monkeypatch.setattr(best, '_rescue', lambda p, b, refined: b)
    plain = plan(threats, s, t, box, cfg)
    assert rescued.feasible and plain.feasible
    assert rescued.seed.startswith('surface route 0') and rescued.seed.endswith('rounds again')
    assert rescued.cost.J < 0.9 * plain.cost.J


def test_each_rescue_run_starts_at_a_higher_penalty_until_it_meets_the_limits(monkeypatch):
    # Restarted at the usual penalty every time, the rounds traded a climb violation back
    # for J run after run; each run now starts RESCUE_GROWTH times higher. Here the first
    # two runs are made to come back stalled, as they did on the measured field.
    import dataclasses
    import threat_planner.core.methods.best as best
    from threat_planner.core.optimise.limits import LimitCheck
    from threat_planner.core.optimise.optimisation import PENALTY_START
    from threat_planner.core.planner import plan, PlannerConfig
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    real, seen, first, met = best.refine, [], [], []

    def refine(p, start, seq, name, **kw):
        cand = real(p, start, seq, name, **kw)
        if not kw.get('warm'):
            if not first and cand.limits_bound:
                first.append(name)
            # The first refined basin stalls (also when refined again from the start).
            return dataclasses.replace(cand, limit_check=stalled) if name in first else cand
        if not kw.get('respace'):
            return cand      # not a rescue run: best._polish
        seen.append(kw['penalty'])
        met.append(cand.limit_check.feasible)
        return cand if len(seen) >= 3 else dataclasses.replace(cand, limit_check=stalled)

    stalled = LimitCheck(31.0, 0.0, 50.0, 0.0, {'climb_deg': 1.0}, 'climb_deg')
    monkeypatch.setattr(best, 'refine', refine)
    monkeypatch.setattr(best, 'RESCUE_MARGIN', 10.0)      # whatever the runner-up's J
    r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.8))
    # From the third run on the real answer is returned; the runs stop at one that meets
    # the limits (here the fourth), and the plan is feasible whichever basin won.
    assert len(seen) >= 3 and met[-1] and not any(met[2:-1])
    assert seen == [PENALTY_START * best.RESCUE_GROWTH ** k for k in range(len(seen))]
    assert r.feasible


def test_without_limits_the_best_surface_route_is_refined_when_a_network_route_won(
        monkeypatch):
    # python -m bench random_fields's field n120 seed 2: a lattice route ranked second by its
    # zigzag J refined 4 % below the winning network route.
    import threat_planner.core.methods.best as best
    from threat_planner.core.planner import plan, PlannerConfig
    from threat_planner.core.world.threats import ThreatField
    n, side = 120, 100.0 * 6.0 ** (1.0 / 3.0)
    rng = np.random.default_rng([102, n])
    positions, intensities = rng.uniform(0.0, side, (n, 3)), rng.uniform(1e5, 4e5, n)
    rng = np.random.default_rng([n, 2])
    s = np.array([0.0, 0.0, rng.uniform(0.0, side)])
    t = np.array([side, side, rng.uniform(0.0, side)])
    threats = ThreatField.from_arrays(positions, intensities * rng.uniform(0.3, 3.0, n))
    box = Box.from_corners([0.0] * 3, [side] * 3)
    cfg = PlannerConfig(w=0.5, max_climb_deg=90.0, max_dive_deg=90.0, min_turn_radius_m=0.0)
    both = plan(threats, s, t, box, cfg)
    monkeypatch.setattr(best, '_lattice_alternatives', lambda p, b, order, route, m: (b, m))
    monkeypatch.setattr(best, 'volume_routes', lambda *args, **kw: [])
    plain = plan(threats, s, t, box, cfg)
    assert both.seed.startswith('surface route') and not plain.seed.startswith('surface')
    assert both.cost.J < 0.97 * plain.cost.J
    # The warm-start lead is over the nearest other refined basin (the network route's
    # or another surface route's), not the screening's ranking.
    assert 0.0 < both.basin_margin <= plain.cost.J / both.cost.J - 1.0 + 1e-12


def test_without_limits_every_surface_basin_is_refined(monkeypatch):
    # The first fresh in-box regression: the lattice ranked the winning surface route
    # third of the four (test_inbox_regressions.py plans it against the yardstick).
    import threat_planner.core.methods.best as best
    from threat_planner.core.planner import plan, PlannerConfig
    sc = load_scenario(DATA / 'inbox_regressions' /
                       'inbox_s1796561117_uniform_n300_f1_w0p5_off.yaml')
    monkeypatch.setattr(best, 'volume_routes', lambda *args, **kw: [])   # surface alone
    names = []
    real = best._refine
    monkeypatch.setattr(best, '_refine', lambda p, start, seq, name, *rest, **kw:
                        names.append(name) or real(p, start, seq, name, *rest, **kw))
    cfg = PlannerConfig(w=0.5, max_climb_deg=90.0, max_dive_deg=90.0, min_turn_radius_m=0.0)
    r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    assert r.seed == 'surface route 2'
    surface = [name for name in names if name.startswith('surface route')]
    assert 'surface route 2' in surface and len(surface) >= 2
    monkeypatch.setattr(best, 'FREE_SURFACE_ROUTES', 2)
    assert plan(sc.threats, sc.start, sc.goal, sc.box, cfg).cost.J > 1.02 * r.cost.J


def test_screening_ties_in_a_refined_basin_are_left_out(monkeypatch):
    """uniform20_0 at w 0.2: all three slope-held seeds are within basins.SCREEN_TIE of the
    best; the first is refined (and wins), the other two lie in its basin at 8 segments
    and are not refined (each cost a gated runner-up's coarse levels for nothing)."""
    from threat_planner.core.methods import best
    from threat_planner.core.methods.basins import same_basin
    from threat_planner.core.planner import plan, PlannerConfig
    ties, names = [], []
    real_screening, real_seed = best.slope_screening, best._refine_seed
    monkeypatch.setattr(best, 'slope_screening', lambda *args: (
        lambda out: ties.extend(out[2]) or out)(real_screening(*args)))
    monkeypatch.setattr(best, '_refine_seed', lambda p, entry, *rest: names.append(entry[0])
                        or real_seed(p, entry, *rest))
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    result = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.2))
    left_out = [(name, path) for name, _, path, _ in ties if name not in names]
    assert result.feasible and len(ties) == 3 and len(left_out) == 2
    assert all(same_basin(PROBLEM, path, result.path) for _, path in left_out)
