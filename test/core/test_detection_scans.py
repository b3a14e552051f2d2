"""Verification of the detection model (issue 43, item 3): H scan by scan, properties.

Every reference (detection_refs.py) is written from the issue's equations, not the code:
P_d from scipy's ncx2, a quadrature of the Rician tail (Marcum's Q_1) and the Swerling 1
closed form; the RCS from an explicit body-frame matrix; H from scipy.integrate.quad per
threat and segment and from a scan-by-scan product and Monte Carlo of detections.
"""

import math

from hypothesis import given, settings, HealthCheck, strategies as st
import numpy as np
import pytest

from detection_refs import ELLIPSOID, F, model, P_FA, PATH, ref_pd_at, ref_snr, THREATS
from threat_planner.core.detection.hazard import path_hazard, profile


# -------------------------------------------------- scan by scan: product and Monte Carlo


def _scan_points(points, step, phase=0.5):
    """Positions and segment directions every `step` metres of arc (first at phase*step)."""
    seg_len = np.linalg.norm(np.diff(points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    s = np.arange(phase * step, cum[-1], step)
    k = np.clip(np.searchsorted(cum, s, side='right') - 1, 0, len(seg_len) - 1)
    t = (s - cum[k]) / seg_len[k]
    e = points[k + 1] - points[k]
    return points[k] + t[:, None] * e, e


def _scan_pd(points, positions, intensities, m, step, phase=0.5):
    """P_d of every threat at every scan, (K, N), from the reference formulas."""
    p, e = _scan_points(points, step, phase)
    return np.array([[ref_pd_at(e[k], p[k], positions[i], intensities[i], m)
                      for i in range(len(positions))] for k in range(len(p))])


# Segment lengths 50, 50, 60, 50 m: with v T = 10 / 2^j m the scans cut every segment into
# whole cells, so the scan sum is the midpoint rule on each segment (the ellipsoid's sigma
# jumps at the kinks) and must converge as T^2.
SCAN_PATH = np.array([[0.0, 0.0, 10.0], [40.0, 30.0, 10.0], [70.0, 30.0, 50.0],
                      [106.0, -18.0, 50.0], [106.0, -48.0, 10.0]])
SCAN_THREATS = np.array([[20.0, 30.0, 0.0], [60.0, 45.0, 40.0], [95.0, -10.0, 30.0],
                         [110.0, -40.0, 0.0], [50.0, 0.0, 60.0]])
STEPS = (10.0, 5.0, 2.5, 1.25, 0.625)          # v T [m]; T = step / 20 m/s
SCAN_MODELS = [(1, 'constant', (2.0,)), (1, 'ellipsoid', ELLIPSOID),
               (0, 'ellipsoid', ELLIPSOID)]
SCAN_IDS = [f'swerling{s}-{k}' for s, k, _ in SCAN_MODELS]


def _weak(m):
    """F scaled so that no threat's SNR along SCAN_PATH exceeds 1: P_d per scan <= 2e-3
    (the Poisson regime, where the scan-by-scan product and 1 - exp(-H) must agree)."""
    p, e = _scan_points(SCAN_PATH, 0.05)
    top = np.array([max(ref_snr(e[k], p[k], SCAN_THREATS[i], F[i], m)
                        for k in range(len(p))) for i in range(len(F))])
    return F / top


@pytest.mark.parametrize('swerling,kind,values', SCAN_MODELS, ids=SCAN_IDS)
def test_scan_sums_converge_to_h_as_the_scan_period_shrinks(swerling, kind, values):
    """sum_k P_d,i(p_k) -> H_i = int P_d,i ds / (v T) as T falls, P_d per scan fixed."""
    gaps = []
    for step in STEPS:
        m = model(swerling, kind, values, speed_mps=20.0, scan_period_s=step / 20.0)
        per = path_hazard(SCAN_PATH, SCAN_THREATS, F, m).per_threat
        scans = _scan_pd(SCAN_PATH, SCAN_THREATS, F, m, step).sum(axis=0)
        gaps.append(np.abs(scans - per).max() / per.max())
    # Each halving of T cuts the gap by about 4 (midpoint rule, second order).
    assert all(b < a / 2.0 for a, b in zip(gaps, gaps[1:])), gaps
    assert gaps[-1] < gaps[0] / 100 and gaps[-1] < 1e-4, gaps


@pytest.mark.parametrize('swerling,kind,values', SCAN_MODELS, ids=SCAN_IDS)
def test_scan_product_converges_to_one_minus_exp_h_in_the_poisson_regime(swerling, kind,
                                                                         values):
    """-ln prod(1 - P_d) / H - 1 = (sum P_d / H - 1) + bias: the scan sum's gap falls as T
    falls; the bias, the p^2 / 2 terms of -ln(1 - p), stays (P_d per scan is fixed) but
    is below max P_d / 2; so the two P_detect agree to that."""
    weak = _weak(model(swerling, kind, values))
    riemann, total, bias = [], [], []
    for step in STEPS:
        m = model(swerling, kind, values, speed_mps=20.0, scan_period_s=step / 20.0)
        rep = path_hazard(SCAN_PATH, SCAN_THREATS, weak, m)
        pd = _scan_pd(SCAN_PATH, SCAN_THREATS, weak, m, step)
        assert pd.max() < 2.5e-3
        log_survival = -np.log1p(-pd).sum()
        riemann.append(abs(pd.sum() / rep.hazard - 1.0))
        bias.append(log_survival / pd.sum() - 1.0)
        total.append(abs(log_survival / rep.hazard - 1.0))
        product = -math.expm1(-log_survival)
        assert product == pytest.approx(rep.p_detect, rel=riemann[-1] + bias[-1] + 1e-9)
    # The weak field's excess is sharply peaked (P_d ~ P_fa^(1/(1 + SNR)), SNR <= 1), so
    # the coarse scans converge slower than T^2, but they do converge.
    assert all(b < a for a, b in zip(riemann, riemann[1:])), riemann
    assert riemann[-1] < riemann[0] / 20, riemann
    assert 0 < max(bias) < 0.5 * 2.5e-3, bias
    assert all(t <= r + b + r * b + 1e-12 for t, r, b in zip(total, riemann, bias))
    assert total[-1] < 0.1 * total[0] and total[-1] < 2e-3, (total, bias)


def test_exp_form_is_a_lower_bound_when_p_d_per_scan_is_large():
    """A property of the model as written: 1 - exp(-H) <= 1 - prod(1 - P_d)."""
    m = model(1, 'constant', (2.0,), speed_mps=20.0, scan_period_s=0.625 / 20.0)
    rep = path_hazard(SCAN_PATH, SCAN_THREATS, F, m)
    pd = _scan_pd(SCAN_PATH, SCAN_THREATS, F, m, m.metres_per_scan)
    assert pd.max() > 0.99
    assert pd.sum() == pytest.approx(rep.hazard, rel=1e-4)
    miss_product = np.prod(1.0 - pd)
    assert miss_product <= math.exp(-pd.sum())
    # Both are certain detection here; the log-survivals differ by the p^2 terms.
    assert -np.log1p(-pd).sum() > 1.05 * rep.hazard


def test_random_scan_phase_averages_to_h_exactly():
    """E over a uniform scan phase of sum_k P_d(p_k) is int P_d ds / (v T) for any T."""
    m = model(0, 'ellipsoid', ELLIPSOID, speed_mps=20.0, scan_period_s=1.0)
    rep = path_hazard(SCAN_PATH, SCAN_THREATS, F, m)
    phases = (np.arange(400) + 0.5) / 400            # midpoint rule over the phase
    total = 0.0
    for ph in phases:
        total += _scan_pd(SCAN_PATH, SCAN_THREATS, F, m, m.metres_per_scan, ph).sum()
    mean = total / len(phases)
    assert mean == pytest.approx(rep.hazard, rel=2e-3)


def test_monte_carlo_of_detections_agrees_with_the_product():
    m = model(1, 'ellipsoid', ELLIPSOID, speed_mps=20.0, scan_period_s=0.125)
    weak = 0.1 * _weak(m)
    pd = _scan_pd(SCAN_PATH, SCAN_THREATS, weak, m, m.metres_per_scan)
    exact = 1.0 - np.prod(1.0 - pd)
    rng = np.random.default_rng(20261207)
    trials = 200_000
    seen = np.zeros(trials, bool)
    for row in pd:                     # one scan: every threat draws independently
        seen |= (rng.random((trials, len(row))) < row).any(axis=1)
    estimate = seen.mean()
    sigma = math.sqrt(exact * (1 - exact) / trials)
    assert abs(estimate - exact) < 4.0 * sigma, (estimate, exact, sigma)
    # And 1 - exp(-H) of the continuous model is within the same tolerance plus the
    # Poisson bias (max P_d per scan) and the scan sum's quadrature error.
    rep = path_hazard(SCAN_PATH, SCAN_THREATS, weak, m)
    assert abs(rep.p_detect - estimate) < 4.0 * sigma + exact * (pd.max() + 0.02)


def test_profile_is_the_reference_p_d_along_the_path():
    m = model(1, 'ellipsoid', ELLIPSOID)
    s, values = profile(PATH, THREATS, F, m, per_segment=4)
    assert values.shape == (len(F), 4 * (len(PATH) - 1))
    assert np.all(np.diff(s) > 0)
    t = (np.arange(4) + 0.5) / 4
    k = 1
    a, b = PATH[k], PATH[k + 1]
    for j, tj in enumerate(t):
        for i in range(len(F)):
            want = ref_pd_at(b - a, a + tj * (b - a), THREATS[i], F[i], m)
            assert values[i, 4 * k + j] == pytest.approx(want, rel=1e-11)


# --------------------------------------------------------------------------- properties

_PROPS = settings(max_examples=60, database=None, derandomize=True, deadline=None,
                  suppress_health_check=[HealthCheck.too_slow])
coords = st.floats(-100.0, 100.0, allow_nan=False)
point = st.tuples(coords, coords, st.floats(0.0, 60.0))


@st.composite
def cases(draw):
    n_pts = draw(st.integers(2, 4))
    pts = np.array(draw(st.lists(point, min_size=n_pts, max_size=n_pts)), float)
    n_thr = draw(st.integers(1, 3))
    thr = np.array(draw(st.lists(point, min_size=n_thr, max_size=n_thr)), float)
    f = 10.0 ** np.array(draw(st.lists(st.floats(2.0, 9.0), min_size=n_thr,
                                       max_size=n_thr)))
    swerling = draw(st.sampled_from([0, 1]))
    kind, values = draw(st.sampled_from([('constant', (1.0,)), ('ellipsoid', ELLIPSOID)]))
    return pts, thr, f, model(swerling, kind, values)


@_PROPS
@given(cases(), st.floats(1.5, 100.0))
def test_property_hazard_nonnegative_monotone_in_f_and_reversible(case, factor):
    pts, thr, f, m = case
    rep = path_hazard(pts, thr, f, m)
    assert np.all(rep.per_threat >= 0) and rep.hazard >= 0
    assert 0.0 <= rep.p_detect <= 1.0
    length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert np.all(rep.per_threat >= P_FA * length / m.metres_per_scan * (1 - 1e-12))
    louder = path_hazard(pts, thr, f * factor, m)
    assert np.all(louder.per_threat >= rep.per_threat * (1 - 1e-9))
    back = path_hazard(pts[::-1].copy(), thr, f, m)
    # The ellipsoid is symmetric under nose -> -nose (and the wing flips with it).
    np.testing.assert_allclose(back.per_threat, rep.per_threat, rtol=1e-8)
