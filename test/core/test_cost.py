"""Closed-form cost (eq. 15-17): accuracy, stability near threats, gradient."""

import numpy as np
import pytest
from scipy.integrate import quad

from threat_planner.core.cost.closed_form import (cost_and_gradient, pair_threat_costs, path_cost,
                                                  segment_integrals, segment_threat_costs)


def _quad_integral(a, b, p):
    """Adaptive quadrature of ds / |x(s) - p|^4, split at the foot point's neighbourhood."""
    length = np.linalg.norm(b - a)
    u = (b - a) / length
    t0 = float(np.dot(p - a, u))
    h = float(np.linalg.norm((p - a) - t0 * u))
    breaks = sorted({min(max(t0 + k * h, 0.0), length) for k in (-30, -3, -1, 0, 1, 3, 30)})
    total = 0.0
    for lo, hi in zip([0.0] + breaks, breaks + [length]):
        if hi > lo:
            total += quad(lambda s: 1.0 / np.sum((a + s * u - p) ** 2) ** 2, lo, hi,
                          epsabs=0.0, epsrel=1e-12, limit=200)[0]
    return total


def test_closed_form_matches_adaptive_quadrature():
    rng = np.random.default_rng(1)
    worst = 0.0
    for trial in range(200):
        a, b, p = rng.uniform(-10, 10, (3, 3))
        if trial % 2:
            # Threats close to the segment's line, on it or beyond its ends.
            n = np.cross(b - a, rng.normal(size=3))
            n /= np.linalg.norm(n)
            p = a + rng.uniform(-0.5, 1.5) * (b - a) + n * 10 ** rng.uniform(-3, 0)
        got = segment_integrals(a[None], b[None], p[None])[0, 0]
        want = _quad_integral(a, b, p)
        worst = max(worst, abs(got - want) / want)
    assert worst < 1e-8


def test_threat_on_the_line_beyond_the_segment_is_exact():
    # h = 0 exactly: integral of dt / t^4 from 1 to 3 = (1 - 1/27) / 3.
    a, b, p = np.array([1.0, 0, 0]), np.array([3.0, 0, 0]), np.zeros(3)
    got = segment_integrals(a[None], b[None], p[None])[0, 0]
    assert got == pytest.approx((1 - 1 / 27) / 3, rel=1e-14)


def test_near_line_threat_is_stable():
    # As h -> 0 the integral tends to the h = 0 value; no cancellation blow-up.
    a, b = np.array([1.0, 0, 0]), np.array([3.0, 0, 0])
    exact = (1 - 1 / 27) / 3
    for h in (1e-3, 1e-6, 1e-9, 1e-12):
        got = segment_integrals(a[None], b[None], np.array([[0.0, h, 0.0]]))[0, 0]
        assert got == pytest.approx(exact, rel=max(10 * h, 1e-13))


def test_threat_on_the_segment_costs_infinity():
    a, b = np.array([[0.0, 0, 0]]), np.array([[2.0, 0, 0]])
    assert np.isinf(segment_integrals(a, b, np.array([[1.0, 0, 0]]))[0, 0])
    assert np.isinf(segment_integrals(a, b, np.array([[0.0, 0, 0]]))[0, 0])


def test_threat_cost_is_additive_and_direction_free():
    rng = np.random.default_rng(2)
    pos, f = rng.uniform(0, 10, (6, 3)), rng.uniform(1, 5, 6)
    a, b = np.array([[0.0, 1, 2]]), np.array([[9.0, 8, 3]])
    mid = 0.37 * a + 0.63 * b
    whole = segment_threat_costs(a, b, pos, f)[0]
    parts = segment_threat_costs(np.vstack([a, mid]), np.vstack([mid, b]), pos, f).sum()
    assert parts == pytest.approx(whole, rel=1e-12)
    assert segment_threat_costs(b, a, pos, f)[0] == pytest.approx(whole, rel=1e-12)


def test_path_cost_combines_length_and_threat():
    pts = np.array([[0.0, 0, 0], [3, 4, 0], [3, 4, 12]])
    pos, f = np.array([[10.0, 0, 0]]), np.array([2.0])
    c = path_cost(pts, pos, f, 0.3)
    assert c.J_L == pytest.approx(17.0)
    j_r = segment_threat_costs(pts[:-1], pts[1:], pos, f).sum()
    assert c.J_R == pytest.approx(j_r)
    assert c.J == pytest.approx(0.3 * j_r + 0.7 * 17.0)
    assert path_cost(pts, np.zeros((0, 3)), np.zeros(0), 0.3).J == pytest.approx(0.7 * 17)


def _numeric_gradient(fun, x, eps=1e-6):
    g = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        d = np.zeros_like(x)
        d[idx] = eps
        g[idx] = (fun(x + d) - fun(x - d)) / (2 * eps)
    return g


@pytest.mark.parametrize('use_pairs', [False, True])
def test_gradient_matches_finite_differences(use_pairs):
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 10, (9, 3))
    pos, f = rng.uniform(0, 10, (7, 3)), rng.uniform(1, 5, 7)
    pairs = None
    if use_pairs:
        seg, thr = np.meshgrid(np.arange(8), np.arange(7), indexing='ij')
        pairs = (seg.ravel(), thr.ravel())
    j, g = cost_and_gradient(pts, pos, f, 0.6, pairs)
    assert j == pytest.approx(path_cost(pts, pos, f, 0.6).J, rel=1e-12)
    num = _numeric_gradient(lambda x: cost_and_gradient(x, pos, f, 0.6)[0], pts)
    assert np.max(np.abs(num - g)) < 1e-6 * np.max(np.abs(g))


def test_pair_costs_equal_dense_costs_over_all_pairs():
    rng = np.random.default_rng(4)
    a, b = rng.uniform(0, 10, (5, 3)), rng.uniform(0, 10, (5, 3))
    pos, f = rng.uniform(0, 10, (4, 3)), rng.uniform(1, 2, 4)
    seg, thr = np.meshgrid(np.arange(5), np.arange(4), indexing='ij')
    dense = segment_threat_costs(a, b, pos, f)
    assert pair_threat_costs(a, b, pos, f, seg.ravel(), thr.ravel()) == pytest.approx(dense)
