"""The compiled kernels agree with the numpy reference they replace on the hot path."""

import numpy as np
import pytest
from scipy.optimize import minimize

from threat_planner.core.cost.closed_form import (cost_and_gradient, pair_threat_costs, path_cost,
                                                  segment_threat_costs)
from threat_planner.core.cost.kernels import (_FROZEN_C2, _FROZEN_C3, _frozen, _NO_PAIRS,
                                              cost_gradient, path_cost as compiled_path_cost,
                                              segment_costs)
from threat_planner.core.cost.near_kernels import near_segment_costs
from threat_planner.core.optimise.lbfgs import _objective, _tri_solve, minimise
from threat_planner.core.optimise.limit_kernels import LimitTerm, measure
from threat_planner.core.optimise.limits import climb_angles, FlightLimits, turn_radii
from threat_planner.core.world.threats import ThreatField


def _segments(rng, n=300):
    a = rng.uniform(0, 100, (n, 3))
    b = a + rng.normal(0, 8, (n, 3))
    b[::17] = a[::17]                       # zero-length segments cost nothing
    return a, b


def test_segment_costs_match_the_numpy_closed_form():
    rng = np.random.default_rng(0)
    a, b = _segments(rng)
    pos = rng.uniform(0, 100, (200, 3))
    f = rng.uniform(0.5, 20, 200)
    pos[0] = 0.3 * a[5] + 0.7 * b[5]        # a threat on segment 5: infinite cost
    pos[1] = 0.5 * (a[6] + b[6]) + 1e-6     # a near-line threat: the series branch
    ref = segment_threat_costs(a, b, pos, f)
    got = segment_costs(a, b, pos, f)
    assert np.isinf(got[5]) and np.isinf(ref[5])
    ok = np.isfinite(ref)
    np.testing.assert_allclose(got[ok], ref[ok], rtol=1e-12)
    seg = rng.integers(0, len(a), 4000)
    thr = rng.integers(0, len(pos), 4000)
    ref = pair_threat_costs(a, b, pos, f, seg, thr)
    got = segment_costs(a, b, pos, f, (seg, thr))
    ok = np.isfinite(ref)
    assert np.array_equal(np.isfinite(got), ok)
    np.testing.assert_allclose(got[ok], ref[ok], rtol=1e-12)


def test_compiled_path_cost_is_the_reference_cost():
    rng = np.random.default_rng(1)
    pts = np.cumsum(rng.uniform(0.5, 4, (41, 3)), axis=0)
    pos, f = rng.uniform(0, 100, (30, 3)), rng.uniform(1, 10, 30)
    ref, got = path_cost(pts, pos, f, 0.4), compiled_path_cost(pts, pos, f, 0.4)
    assert got.J == pytest.approx(ref.J, rel=1e-13)
    assert got.J_R == pytest.approx(ref.J_R, rel=1e-13)
    assert got.J_L == ref.J_L


@pytest.mark.parametrize('order', ['dense', 'by segment', 'shuffled'])
def test_compiled_gradient_is_the_numpy_closed_form(order):
    # The kernel sums each segment's run of pairs in registers: every pair order (a
    # cut-off's pairs come sorted by segment, any order must do) gives numpy's J and
    # gradient, zero-length segments included.
    rng = np.random.default_rng(7)
    pts = np.cumsum(rng.uniform(-3, 6, (31, 3)), axis=0)
    pts[9] = pts[8]
    pos, f = rng.uniform(-10, 120, (25, 3)), rng.uniform(1, 50, 25)
    pairs = None
    if order != 'dense':
        seg = rng.integers(0, 30, 500)
        thr = rng.integers(0, 25, 500)
        if order == 'by segment':
            keep = np.argsort(seg, kind='stable')
            seg, thr = seg[keep], thr[keep]
        pairs = (seg, thr)
    j_ref, g_ref = cost_and_gradient(pts, pos, f, 0.6, pairs)
    j, g = cost_gradient(pts, pos, f, 0.6, pairs)
    assert j == pytest.approx(j_ref, rel=1e-12)
    np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-12 * np.abs(g_ref).max())


@pytest.mark.parametrize('layout', ['spread', 'flat', 'one', 'line'])
def test_grid_cut_off_costs_match_the_tree_query(layout):
    rng = np.random.default_rng(2)
    pos = rng.uniform(0, 100, (500, 3))
    if layout == 'flat':
        pos[:, 2] = 50.0                    # coplanar threats: one layer of cells
    elif layout == 'one':
        pos = pos[:1]
    elif layout == 'line':
        pos[:, 1:] = 10.0
    f = rng.uniform(0.5, 5, len(pos))
    threats = ThreatField(pos, f)
    a, b = _segments(rng, 400)
    radius = 12.0
    seg, thr, bound = threats.near_pairs(a, b, radius)
    ref = pair_threat_costs(a, b, pos, f, seg, thr)
    got, got_bound = near_segment_costs(a, b, pos, f, radius)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(got_bound, bound, rtol=1e-12, atol=1e-300)


def test_measure_matches_the_limit_definitions():
    rng = np.random.default_rng(3)
    for trial in range(600):
        n = int(rng.integers(2, 12))
        p = rng.normal(0, 10, (n, 3))
        if trial % 3 == 0:
            p[rng.integers(1, n)] = p[rng.integers(0, n)]        # repeated vertex
        if trial % 5 == 0:                                       # collinear, reversals
            p = np.cumsum(np.tile([[1.0, 0.0, 0.3]], (n, 1)), 0) * rng.choice([1, -1], (n, 1))
        ang = climb_angles(p)
        ref = (ang.max(initial=-90.0), (-ang).max(initial=-90.0),
               turn_radii(p).min(initial=np.inf), (p[1:-1, 2] - 1.0).min(initial=np.inf))
        got = measure(p, 1.0)
        for r, g in zip(ref, got):
            assert g == pytest.approx(float(r), rel=1e-12, abs=1e-12)


def _problem(n=25, with_limits=True):
    rng = np.random.default_rng(4)
    s, t = np.array([5.0, 5.0, 10.0]), np.array([95.0, 90.0, 60.0])
    x = s + np.linspace(0, 1, n + 1)[:, None] * (t - s)
    x[1:-1] += rng.normal(0, 4, (n - 1, 3))
    pos = _frozen(rng.uniform(10, 90, (15, 3)))
    f = _frozen(rng.uniform(5, 50, 15))
    term = LimitTerm(FlightLimits(20.0, 20.0, 15.0), n + 1) if with_limits else None
    return x, pos, f, term


def test_objective_gradient_matches_finite_differences():
    x, pos, f, term = _problem()
    n1 = len(x)
    lam = np.random.default_rng(5).uniform(0, 0.5, term.rows)

    def value(z):
        g = np.zeros(3 * n1)
        v = _objective(z, n1, pos, f, 0.6, _NO_PAIRS, _NO_PAIRS, _FROZEN_C2, _FROZEN_C3,
                       0.01, 0.5, 80.0, term.kernel_args(), lam, 30.0,
                       np.zeros(term.rows), np.zeros((n1, 3)), g, np.zeros(2))
        return v, g

    z = x.reshape(-1).copy()
    _, g = value(z)
    for k in range(3, 3 * n1 - 3, 7):
        e = np.zeros_like(z)
        e[k] = 1e-6
        fd = (value(z + e)[0] - value(z - e)[0]) / 2e-6
        assert g[k] == pytest.approx(fd, rel=1e-4, abs=1e-7)


@pytest.mark.parametrize('precondition', [True, False])
def test_lbfgs_reaches_scipy_lbfgsb_within_bounds(precondition):
    """Same objective, same bounds: the compiled run ends at scipy's J or lower."""
    x, pos, f, _ = _problem(with_limits=False)
    n1 = len(x)
    lo = np.tile([0.0, 0.0, 20.0], (n1, 1))
    hi = np.tile([100.0, 100.0, 45.0], (n1, 1))
    lo[0] = hi[0] = x[0]
    lo[-1] = hi[-1] = x[-1]
    off = np.zeros(7), np.zeros(0), np.zeros((n1, 3))

    def fun(z):
        g = np.zeros(3 * n1)
        v = _objective(z, n1, pos, f, 0.5, _NO_PAIRS, _NO_PAIRS, _FROZEN_C2, _FROZEN_C3,
                       0.0, 0.0, 1.0, off[0], off[1], 1.0, off[1], off[2], g, np.zeros(2))
        return v, g

    start = np.clip(x, lo, hi).reshape(-1)
    ref = minimize(fun, start, jac=True, method='L-BFGS-B',
                   bounds=list(zip(lo.reshape(-1), hi.reshape(-1))),
                   options={'ftol': 1e-12, 'gtol': 1e-10, 'maxiter': 5000})
    z, val, nit, nfev = minimise(start, lo.reshape(-1), hi.reshape(-1), pos, f, 0.5,
                                 (_NO_PAIRS, _NO_PAIRS), _FROZEN_C2, _FROZEN_C3, 0.0, 0.0,
                                 1.0, off[0], off[1], 1.0, off[1], off[2], 5000, 1e-12,
                                 precondition=precondition)
    assert nfev >= nit > 0
    assert val <= ref.fun * (1 + 1e-6)
    assert np.all(z >= lo.reshape(-1)) and np.all(z <= hi.reshape(-1))
    assert np.array_equal(z.reshape(n1, 3)[[0, -1]], x[[0, -1]])
    # Some vertices rest on the floor or the ceiling: the bounds were active, not idle.
    z_inner = z.reshape(n1, 3)[1:-1, 2]
    assert np.any(np.isclose(z_inner, 45.0) | np.isclose(z_inner, 20.0))


def test_multipliers_carry_to_a_finer_path_as_densities():
    limits = FlightLimits(30.0, 25.0, 10.0)
    coarse, fine = LimitTerm(limits, 11), LimitTerm(limits, 21)
    lam = np.concatenate([np.full(10, 0.4), np.linspace(0, 1, 10), np.full(9, 0.2),
                          np.full(9, 0.3)])
    out = fine.transfer((coarse, lam))
    assert out.shape == (fine.rows,)
    np.testing.assert_allclose(out[:20], 0.2)                 # climb: half per segment
    assert out[20] == pytest.approx(0.0) and out[39] == pytest.approx(0.5)
    np.testing.assert_allclose(out[40:59], 0.1)               # radius rows, each side
    np.testing.assert_allclose(out[59:], 0.15)
    # The total (the integral of the density) is kept.
    assert out[:20].sum() == pytest.approx(lam[:10].sum())


def _ends_fixed():
    """The problem without limits, flat: start, bounds fixing only the ends, empty term."""
    x, pos, f, _ = _problem(with_limits=False)
    n1 = len(x)
    lo = np.full(3 * n1, -np.inf)
    hi = np.full(3 * n1, np.inf)
    lo[:3] = hi[:3] = x[0]
    lo[-3:] = hi[-3:] = x[-1]
    off = np.zeros(7), np.zeros(0), np.zeros((n1, 3))
    return x.reshape(-1).copy(), lo, hi, pos, f, off, n1


def test_lbfgs_moves_no_vertex_further_than_max_step_per_iteration():
    start, lo, hi, pos, f, off, n1 = _ends_fixed()
    moved = []
    for iterations in (1, 2, 3):
        z, _, nit, _ = minimise(start, lo, hi, pos, f, 0.5, (_NO_PAIRS, _NO_PAIRS),
                                _FROZEN_C2, _FROZEN_C3, 0.0, 0.0, 1.0, off[0], off[1], 1.0,
                                off[1], off[2], iterations, 0.0, max_step=0.5)
        assert nit == iterations
        moved.append(np.linalg.norm((z - start).reshape(n1, 3), axis=1).max())
    assert moved[0] <= 0.5 + 1e-12
    assert all(m <= 0.5 * k + 1e-12 for k, m in enumerate(moved, 1))
    # Unbounded, the first quasi-Newton steps go further (the cap is what held them).
    z, _, _, _ = minimise(start, lo, hi, pos, f, 0.5, (_NO_PAIRS, _NO_PAIRS), _FROZEN_C2,
                          _FROZEN_C3, 0.0, 0.0, 1.0, off[0], off[1], 1.0, off[1], off[2], 3,
                          0.0)
    assert np.linalg.norm((z - start).reshape(n1, 3), axis=1).max() > moved[2]


def test_preconditioner_solves_the_second_difference_system_of_the_free_vertices():
    """Held coordinates (the ends, a vertex on a wall) are fixed: their rows decouple."""
    rng = np.random.default_rng(5)
    n1 = 12
    free = np.ones(3 * n1)
    free[:3] = free[-3:] = 0.0
    free[3 * 4 + 2] = free[3 * 5 + 2] = free[3 * 8] = 0.0
    v = rng.normal(size=3 * n1)
    out = np.full(3 * n1, np.nan)
    _tri_solve(v, free, n1, out, np.zeros(n1), np.zeros(n1))
    lap = 2 * np.eye(n1) - np.eye(n1, k=1) - np.eye(n1, k=-1)
    for axis in range(3):
        idx = [i for i in range(n1) if free[3 * i + axis]]
        cols = [3 * i + axis for i in idx]
        np.testing.assert_allclose(out[cols], np.linalg.solve(lap[np.ix_(idx, idx)], v[cols]),
                                   rtol=1e-12, atol=1e-12)
    assert np.all(out[free == 0.0] == 0.0)


def test_lbfgs_stops_at_the_first_iterate_beyond_reach():
    """Every iterate before the last is within reach; the last is the first one out."""
    start, lo, hi, pos, f, off, n1 = _ends_fixed()

    def run(iterations, reach=np.inf):
        return minimise(start, lo, hi, pos, f, 0.5, (_NO_PAIRS, _NO_PAIRS), _FROZEN_C2,
                        _FROZEN_C3, 0.0, 0.0, 1.0, off[0], off[1], 1.0, off[1], off[2],
                        iterations, 0.0, max_step=0.5, reach=reach)

    free = run(200)
    far = np.linalg.norm((free[0] - start).reshape(n1, 3), axis=1).max()
    assert far > 2.0
    z, _, nit, _ = run(200, reach=1.0)
    assert nit < free[2]
    np.testing.assert_array_equal(z, run(nit)[0])          # the same iterates up to there
    out = lambda y: np.linalg.norm((y - start).reshape(n1, 3), axis=1).max()  # noqa: E731
    assert 1.0 < out(z) <= 1.5 + 1e-12
    assert out(run(nit - 1)[0]) <= 1.0


def test_lbfgs_reports_the_minimiser_s_parts_and_scales_itself_exactly():
    """parts = J + spring and J + both spacing terms at the minimiser, as a fresh call
    gives them; scale 0 runs bit for bit as the start's value given."""
    x, pos, f, term = _problem()
    n1 = len(x)
    lo = np.tile([0.0, 0.0, 0.0], (n1, 1)).reshape(-1)
    hi = np.tile([100.0, 100.0, 100.0], (n1, 1)).reshape(-1)
    lo[:3] = hi[:3] = x[0]
    lo[-3:] = hi[-3:] = x[-1]
    lam = np.full(term.rows, 0.1)
    for lim, mu in ((np.zeros(7), 1.0), (term.kernel_args(), 10.0)):
        lam_k = lam if lim[6] else np.zeros(0)

        def value(z, even, scale):
            parts = np.zeros(2)
            v = _objective(z, n1, pos, f, 0.5, _NO_PAIRS, _NO_PAIRS, _FROZEN_C2, _FROZEN_C3,
                           0.01, even, scale, np.zeros(7), np.zeros(0), 1.0, np.zeros(0),
                           np.zeros((n1, 3)), np.zeros(3 * n1), parts)
            return v, parts

        start = x.reshape(-1).copy()
        scale = value(start, 0.3, 1.0)[0]

        def run(s, parts):
            return minimise(start, lo, hi, pos, f, 0.5, (_NO_PAIRS, _NO_PAIRS), _FROZEN_C2,
                            _FROZEN_C3, 0.01, 0.3, s, lim, lam_k, mu,
                            np.zeros(len(lam_k)), np.zeros((n1, 3)), 300, 1e-9,
                            parts=parts)

        given, itself = np.zeros(2), np.zeros(2)
        a, b = run(scale, given), run(0.0, itself)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:] == b[1:] and np.array_equal(given, itself)
        assert a[2] > 5
        j_spring = value(a[0], 0.0, 1.0)[0]
        assert given[0] == j_spring
        assert given[1] / scale == value(a[0], 0.3, scale)[0]


def _pair_geometries(rng, n=3000):
    """Segments from t1 to t1 + ln along a line and threats at distance h off it: every
    ratio |t| / h up to the direct form's reach and past it, ln from 1e-3 h to 20 h.

    Returns the segments' ends, the threats and each pair's condition number: the size of
    the antiderivative's terms over their difference, (h^2 + t^2)^2 / (h^3 ln) at the
    nearer end, by which any closed form of the difference loses digits.
    """
    h = 10.0 ** rng.uniform(-4, 3, n)
    t1 = h * rng.uniform(-12, 12, n)
    ln = h * 10.0 ** rng.uniform(-3, 1.3, n)
    t1[::5] = -0.5 * ln[::5]                    # centred: the subtended angle near pi
    t1[1::7] = h[1::7] * 9.999                  # at the direct form's reach
    a = np.zeros((n, 3))
    a[:, 0] = t1
    b = a.copy()
    b[:, 0] += ln
    off = rng.normal(0, 1, (n, 2))
    off /= np.linalg.norm(off, axis=1)[:, None]
    pos = np.zeros((n, 3))
    pos[:, 1:] = off * h[:, None]
    shift = rng.uniform(-50, 50, (n, 3))        # anywhere, not only at the origin
    near = np.minimum(np.abs(t1), np.abs(t1 + ln))
    near[(t1 < 0) & (t1 + ln > 0)] = 0.0
    cond = (h * h + near * near) ** 2 / (h ** 3 * ln)
    return a + shift, b + shift, pos + shift, cond


def test_both_pair_forms_give_the_numpy_integrals():
    # _direct (one atan of the subtended angle) where both ends lie within ten distances
    # of the foot, _far (split antiderivatives, series) beyond: each pair's I2 and the
    # gradient (I3) match numpy's closed form across the switch, to the digits the
    # difference of antiderivatives leaves (checked against 50-digit mpmath while
    # writing this: at the worst condition both forms were 1e-10 off, alike).
    rng = np.random.default_rng(11)
    a, b, pos, cond = _pair_geometries(rng)
    f = np.ones(len(a))
    idx = np.arange(len(a))
    ref = pair_threat_costs(a, b, pos, f, idx, idx)
    got = segment_costs(a, b, pos, f, (idx, idx))
    assert np.all(np.abs(got - ref) <= (1e-13 + 1e-15 * cond) * np.abs(ref))
    for k in np.flatnonzero(cond < 1e3)[::5]:
        pts = np.array([a[k], b[k], b[k] + [0.0, 0.0, 1e-2 * np.linalg.norm(b[k] - a[k])]])
        j_ref, g_ref = cost_and_gradient(pts, pos[k:k + 1], f[:1], 0.9)
        j, g = cost_gradient(pts, pos[k:k + 1], f[:1], 0.9)
        assert j == pytest.approx(j_ref, rel=1e-11)
        np.testing.assert_allclose(g, g_ref, rtol=1e-8, atol=1e-9 * np.abs(g_ref).max())
