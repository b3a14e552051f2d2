"""Direct J minimisation within the box and the physical flight limits."""

import numpy as np
import pytest

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.cost.kernels import _FROZEN_C2, _FROZEN_C3
from threat_planner.core.optimise.lbfgs import minimise, objective_scale
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.optimise.optimisation import minimise_cost
from threat_planner.core.optimise.smoothing import resample
from threat_planner.core.world.threats import Box, ThreatField


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


def test_a_gate_sees_every_coarser_level_and_stops_where_it_says(problem):
    """A gate that never fires changes nothing; one that fires returns that level's answer."""
    threats, box, start, goal = problem
    x0 = resample(np.vstack([start, [60.0, 40.0, 65.0], goal]), 40)
    limits = FlightLimits(8.0, 8.0, 20.0, 0.0)
    full = minimise_cost(x0, threats, 0.5, box, limits)
    seen = []
    watched = minimise_cost(x0, threats, 0.5, box, limits,
                            gate=lambda pts: seen.append(len(pts)) or False)
    assert full.constrained and seen == [11, 21]           # the 10- and 20-segment levels
    np.testing.assert_array_equal(watched.points, full.points)
    assert [len(a) for a in full.levels] == [11, 21]
    stopped = minimise_cost(x0, threats, 0.5, box, limits, gate=lambda pts: len(pts) == 21)
    assert len(stopped.points) == 21 and len(stopped.levels) == 2
    np.testing.assert_array_equal(stopped.points, full.levels[1])
    assert stopped.evaluations < full.evaluations


def test_prolongation_keeps_a_coarse_arc_s_turn_radius_where_linear_halves_it():
    """Into the finest level: subdivision spreads each turn, interpolation concentrates it."""
    from threat_planner.core.optimise.limit_kernels import measure
    from threat_planner.core.optimise.optimisation import _prolong
    radius = 30.0
    a = np.linspace(0.0, np.pi / 2, 11)
    coarse = np.stack([radius * np.cos(a), radius * np.sin(a), 2.0 * a], axis=1)
    r_coarse = measure(coarse, -1e9)[2]
    fine = _prolong(coarse, 20)
    assert len(fine) == 21
    np.testing.assert_array_equal(fine[[0, -1]], coarse[[0, -1]])
    # Convex combinations of coarse vertices: inside their bounding box.
    assert np.all(fine >= coarse.min(axis=0) - 1e-12)
    assert np.all(fine <= coarse.max(axis=0) + 1e-12)
    assert measure(fine, -1e9)[2] >= 0.95 * r_coarse
    assert measure(resample(coarse, 20), -1e9)[2] <= 0.55 * r_coarse
    # Not a doubling: plain resampling.
    np.testing.assert_allclose(_prolong(coarse, 15), resample(coarse, 15))


def test_the_constrained_answer_is_the_least_j_feasible_round(problem):
    """Every round's J is traced; the one returned is the least feasible of them."""
    from threat_planner.core.optimise import optimisation as opt
    threats, box, start, goal = problem
    limits = FlightLimits(8.0, 8.0, 40.0, 0.0)
    x0 = resample(np.vstack([start, [60.0, 40.0, 65.0], goal]), 20)
    level = opt._Level(x0, threats, 0.5, box, limits, None, 1e-6, opt._Stats())
    _, _, best = level.constrained(x0, None, opt.PENALTY_START, 200)
    done = level.trace[~np.isnan(level.trace[:, 0])]
    feasible = done[done[:, 1] == 1.0, 0]
    # Two feasible rounds here, the second 1e-4 higher: the first is the one returned.
    assert len(feasible) >= 2
    assert check_limits(best, limits, 0.0).feasible
    assert level.value(best, 0.0) == feasible.min()
    # With a gain any feasible round lowers J by less than (100 %), the second one stops.
    _, _, early = level.constrained(x0, None, opt.PENALTY_START, 200, gain=1.0)
    done = level.trace[~np.isnan(level.trace[:, 0])]
    assert done[-1, 1] == 1.0 and np.sum(done[:, 1]) == 2.0
    assert check_limits(early, limits, 0.0).feasible


def _reference_rounds(level, x, lam, mu, maxiter, rounds, gain):
    """The rounds as they ran in Python before they were compiled (for the cross-check)."""
    from threat_planner.core.optimise import optimisation as opt
    from threat_planner.core.optimise.limit_kernels import LimitTerm
    x = level.clip(x)
    level.pick_pairs(x)
    even = opt.EVEN_SPACING_WEIGHT * level.spring_unit
    scale = float(objective_scale(level.value(x, even)))
    term = LimitTerm(level.limits.tightened(opt.ANGLE_MARGIN_DEG, opt.RADIUS_MARGIN), level.n)
    lam = np.zeros(term.rows) if lam is None else term.transfer(lam)
    prev_violation, prev_f, prev_j, best, picked = np.inf, np.inf, np.nan, None, x
    for _ in range(rounds):
        if level.cutoff is not None and float(np.max(np.linalg.norm(
                x - picked, axis=1))) >= opt.REPICK_CUTOFFS * level.cutoff:
            level.pick_pairs(x)
            picked = x
        z, _, nit, nfev = minimise(
            x.reshape(-1).copy(), level.lo.reshape(-1), level.hi.reshape(-1), level.pairs[2],
            level.intensities, level.w, level.pairs[:2], _FROZEN_C2, _FROZEN_C3,
            level.spring, even, scale, term.kernel_args(), lam, mu, np.zeros(term.rows),
            np.zeros((level.n, 3)), maxiter, level.tolerance, max_step=level.max_step,
            precondition=level.precondition)
        level.stats.add(nit, nfev)
        x = z.reshape(level.n, 3)
        c = term.values(x)
        violation = float(np.max(-c, initial=0.0))
        lam = np.maximum(0.0, lam - mu * c)
        f = level.value(x, even, scale)
        feasible = check_limits(x, level.limits, level.floor).feasible
        j_round = level.value(x, 0.0)
        if not feasible and abs(j_round - prev_j) <= 1e-9 * abs(j_round):
            x = _unfolded(x)
        prev_j = j_round
        if feasible:
            j = level.value(x, 0.0)
            stop = gain is not None and best is not None and best[0] - j < gain * abs(j)
            if best is None or j < best[0]:
                best = (j, x)
            if stop or abs(prev_f - f) <= opt.OUTER_TOLERANCE * max(abs(f), 1.0):
                break
        if violation > 0.25 * prev_violation:
            mu *= opt.PENALTY_GROWTH
        prev_violation, prev_f = violation, f
    return x, lam, None if best is None else best[1]


def _unfolded(x):
    """x with every vertex folded onto a neighbour moved to the middle of its neighbours."""
    from threat_planner.core.optimise.lagrangian_kernels import _unfold, FOLDED
    z = x.reshape(-1).copy()
    _unfold(z, FOLDED)
    return z.reshape(x.shape)


def test_a_folded_vertex_moves_to_the_middle_of_its_neighbours_and_the_path_stays():
    """The turn rows' gradients grow as 1 / length at a folded vertex and L-BFGS stalls
    there; moved to its neighbours' middle, the polyline (so J) is the one it was."""
    from threat_planner.core.optimise.lagrangian_kernels import _unfold, FOLDED
    threats = ThreatField.from_arrays([[50.0, 50.0, 50.0], [30.0, 60.0, 40.0]], [2e5, 1e5])
    x = resample(np.vstack([[0.0, 0.0, 40.0], [50.0, 20.0, 80.0], [100.0, 100.0, 70.0]]), 12)
    x[1:-1] += np.random.default_rng(7).normal(0.0, 2.0, (11, 3))
    untouched = x.reshape(-1).copy()
    assert _unfold(untouched, FOLDED) == 0 and np.array_equal(untouched, x.reshape(-1))
    folded = x.copy()
    folded[1] = folded[0] + [0.0, 1e-5, -1e-6]            # onto the start
    folded[8] = folded[7] + [2e-6, 0.0, 0.0]              # onto the vertex before it
    z = folded.reshape(-1).copy()
    assert _unfold(z, FOLDED) == 2
    p = z.reshape(-1, 3)
    np.testing.assert_array_equal(p[1], 0.5 * (folded[0] + folded[2]))
    np.testing.assert_array_equal(p[8], 0.5 * (folded[7] + folded[9]))
    others = [i for i in range(len(p)) if i not in (1, 8)]
    np.testing.assert_array_equal(p[others], folded[others])
    j = [path_cost(q, threats.positions, threats.intensities, 0.5).J for q in (folded, p)]
    assert j[1] == pytest.approx(j[0], rel=1e-6)
    assert min(np.linalg.norm(np.diff(p, axis=0), axis=1)) > FOLDED * 10.0


@pytest.mark.parametrize('cutoff', [None, 12.0])
@pytest.mark.parametrize('gain', [None, 1e-3])
def test_compiled_rounds_run_as_the_python_loop_bit_for_bit(cutoff, gain):
    """Same iterates, multipliers and answer as the loop in Python, with and without a
    cut-off whose pairs are picked again on the way."""
    from threat_planner.core.optimise import optimisation as opt
    rng = np.random.default_rng(11)
    threats = ThreatField.from_arrays(rng.uniform(10, 90, (25, 3)), rng.uniform(2e4, 2e5, 25))
    box = Box.from_corners([0, 0, 0], [100, 100, 100])
    limits = FlightLimits(12.0, 12.0, 30.0, 0.0)
    x0 = resample(np.vstack([[0.0, 0.0, 50.0], [55.0, 30.0, 75.0], [100.0, 100.0, 45.0]]), 20)
    picks = []
    compiled = opt._Level(x0, threats, 0.5, box, limits, cutoff, 1e-6, opt._Stats())
    python = opt._Level(x0, threats, 0.5, box, limits, cutoff, 1e-6, opt._Stats())
    for level in (compiled, python):
        original = level.pick_pairs
        level.pick_pairs = lambda p, o=original, lv=level: picks.append(lv) or o(p)
    x, (_, lam), best = compiled.constrained(x0, None, opt.PENALTY_START, 200, gain=gain)
    rx, rlam, rbest = _reference_rounds(python, x0, None, opt.PENALTY_START, 200,
                                        opt.MAX_OUTER, gain)
    np.testing.assert_array_equal(x, rx)
    np.testing.assert_array_equal(lam, rlam)
    assert (best is None) == (rbest is None)
    if best is not None:
        np.testing.assert_array_equal(best, rbest)
    assert picks.count(compiled) == picks.count(python) >= (1 if cutoff is None else 2)
    assert vars(compiled.stats) == vars(python.stats) and compiled.stats.rounds >= 3


def test_a_known_broken_box_optimum_goes_straight_to_the_rounds(problem, monkeypatch):
    """box_broken: no box-only run, and still a feasible answer below the start's J."""
    from threat_planner.core.optimise import optimisation as opt
    threats, box, start, goal = problem
    limits = FlightLimits(8.0, 8.0, 20.0, 0.0)
    x0 = resample(np.vstack([start, [60.0, 40.0, 55.0], goal]), 20)
    calls = []
    original = opt._Level.unconstrained
    monkeypatch.setattr(opt._Level, 'unconstrained',
                        lambda self, x, maxiter: calls.append(1) or original(self, x, maxiter))
    res = minimise_cost(x0, threats, 0.5, box, limits, box_broken=True)
    assert calls == [] and res.constrained
    assert check_limits(res.points, limits, 0.0).feasible
    j0 = path_cost(x0, threats.positions, threats.intensities, 0.5).J
    assert path_cost(res.points, threats.positions, threats.intensities, 0.5).J < j0
    minimise_cost(x0, threats, 0.5, box, limits)
    assert calls                                   # without it the box-only run comes first


def test_the_hot_loop_s_feasibility_is_check_limits_verdict():
    """meets_limits and the compiled rounds' check say what check_limits(...).feasible
    says, near every limit."""
    from threat_planner.core.optimise.lagrangian_kernels import _meets
    from threat_planner.core.optimise.limits import meets_limits
    rng = np.random.default_rng(3)
    limits = FlightLimits(20.0, 25.0, 15.0, 5.0)
    verdicts = set()
    for _ in range(300):
        # Arcs around every limit: radius 10-20 m, climbing or diving 15-30 deg, from
        # 3-8 m up.
        radius, slope = rng.uniform(10.0, 20.0), np.radians(rng.uniform(15.0, 30.0))
        arc = np.linspace(0.0, 1.5, 12)
        sign = rng.choice([-1.0, 1.0])
        pts = np.column_stack([radius * np.cos(arc), radius * np.sin(arc),
                               rng.uniform(3.0, 8.0) + sign * radius * arc * np.tan(slope)])
        pts[:, 2] -= min(0.0, pts[1:-1, 2].min() - rng.uniform(3.0, 8.0))
        full = check_limits(pts, limits, 0.0)
        assert meets_limits(pts, limits, 0.0) == full.feasible
        assert _meets(np.ascontiguousarray(pts), 0.0, np.array(
            [limits.max_climb_deg, limits.max_dive_deg, limits.min_turn_radius_m,
             limits.min_altitude_m])) == full.feasible
        verdicts.update(full.violations or {'none'})
    assert verdicts == {'none', 'climb_deg', 'dive_deg', 'turn_radius_m', 'altitude_m'}


def test_constrained_only_runs_the_rounds_at_the_start_s_resolution(problem, monkeypatch):
    """A warm start: no box-only run and no coarser level, whether or not it meets the
    limits; where it does not, the answer still does."""
    from threat_planner.core.optimise import optimisation as opt
    threats, box, start, goal = problem
    limits = FlightLimits(8.0, 8.0, 20.0, 0.0)
    calls = []
    original = opt._Level.unconstrained
    monkeypatch.setattr(opt._Level, 'unconstrained',
                        lambda self, x, maxiter: calls.append(1) or original(self, x, maxiter))
    kinked = resample(np.vstack([start, [60.0, 40.0, 75.0], goal]), 40)
    assert not check_limits(kinked, limits, 0.0).feasible
    res = minimise_cost(kinked, threats, 0.5, box, limits, constrained_only=True)
    assert calls == [] and res.levels == () and res.constrained
    assert check_limits(res.points, limits, 0.0).feasible
    minimise_cost(kinked, threats, 0.5, box, limits)
    assert calls and len(minimise_cost(kinked, threats, 0.5, box, limits).levels) == 2
