"""Verification of the detection model (issue 43, item 3) against independent references.

Every reference here is written from the issue's equations, not from the module's code:
P_d from scipy's ncx2, a quadrature of the Rician tail (Marcum's Q_1) and the Swerling 1
closed form; the RCS from an explicit body-frame matrix; H from scipy.integrate.quad per
threat and segment and from a scan-by-scan product and Monte Carlo of detections.
"""

import math

from hypothesis import given, settings, HealthCheck, strategies as st
import numpy as np
import pytest
from scipy import integrate, special, stats

from threat_planner.core.detection.hazard import (hazard_and_gradient, layout, path_hazard,
                                                   profile)
from threat_planner.core.detection.model import DetectionModel, p_detect_scan, snr

UP = np.array([0.0, 0.0, 1.0])
P_FA = 1.0e-6
ELLIPSOID = (3.0, 1.0, 0.5)

# --------------------------------------------------------------------------- references


def ref_pd(snr_value, p_fa, swerling):
    """P_d per scan from the issue's formulas (scalar)."""
    x = -2.0 * math.log(p_fa)
    if swerling == 1:
        return p_fa ** (1.0 / (1.0 + snr_value))
    return float(stats.ncx2.sf(x, 2, 2.0 * snr_value))


def marcum_q1(a, b):
    """Q_1(a, b) by quadrature of the Rician density: int_b^inf x e^(-(x^2+a^2)/2) I_0(ax)."""
    def density(x):
        # e^(-(x^2 + a^2)/2) I_0(a x) = e^(-(x - a)^2 / 2) ive(0, a x)
        return x * math.exp(-0.5 * (x - a) ** 2) * special.ive(0, a * x)
    top = max(a, b) + 40.0
    if b < a:
        # Q_1 near 1: 1 - integral from 0 to b, done on the short side.
        below, _ = integrate.quad(density, 0.0, b, epsabs=0, epsrel=1e-13, limit=200)
        return 1.0 - below
    value, _ = integrate.quad(density, b, top, epsabs=0, epsrel=1e-13, limit=200)
    return value


def body_frame(e):
    """Rows: nose, right wing (horizontal), down, for a non-vertical direction e."""
    n = np.asarray(e, float) / np.linalg.norm(e)
    r = np.cross(n, UP)
    r /= np.linalg.norm(r)
    d = np.cross(n, r)
    return np.array([n, r, d])


def ref_sigma(e, p, q, model):
    """The issue's sigma: the ellipsoid seen along the unit line of sight in the body frame."""
    if model.rcs_kind == 'constant':
        return model.rcs_values[0]
    a, b, c = model.rcs_values
    g = np.asarray(q, float) - np.asarray(p, float)
    u = body_frame(e) @ (g / np.linalg.norm(g))
    return math.pi * (a * b * c) ** 2 / (a * a * u[0] ** 2 + b * b * u[1] ** 2
                                          + c * c * u[2] ** 2) ** 2


def ref_snr(e, p, q, f, model):
    g = np.asarray(q, float) - np.asarray(p, float)
    return f * ref_sigma(e, p, q, model) / np.dot(g, g) ** 2


def ref_pd_at(e, p, q, f, model):
    g = np.asarray(q, float) - np.asarray(p, float)
    if not np.any(g):
        return 1.0
    return ref_pd(ref_snr(e, p, q, f, model), model.p_fa, model.swerling)


def ref_hazard(points, positions, intensities, model, pieces=None):
    """Each threat's H_i by scipy quad per threat per segment (floor P_fa l exact)."""
    points = np.asarray(points, float)
    per = np.zeros(len(positions))
    todo = []
    if pieces is None:
        for k in range(len(points) - 1):
            for i in range(len(positions)):
                todo.append((k, i, 0.0, 1.0))
    else:
        todo = list(zip(*pieces))
    for k, i, f0, f1 in todo:
        a, b = points[k], points[k + 1]
        e = b - a
        length = np.linalg.norm(e)
        if length == 0 or f1 <= f0:
            continue
        q = positions[i]

        def excess(t):
            return ref_pd_at(e, a + t * e, q, intensities[i], model) - model.p_fa
        t_near = float(np.clip(np.dot(q - a, e) / np.dot(e, e), f0, f1))
        # Breaks at the closest approach and at 1/8 .. 2^20 radar ranges either side, so
        # each quad sees one smooth rise or fall (a long segment's steep Swerling 0 step
        # is otherwise a needle to quad).
        reach = (intensities[i] * model.largest_rcs) ** 0.25 / length
        offsets = reach * 2.0 ** np.arange(-3, 21)
        breaks = np.concatenate([[f0, t_near, f1], t_near - offsets, t_near + offsets])
        breaks = np.unique(np.clip(breaks, f0, f1))
        value = sum(integrate.quad(excess, lo, hi, epsabs=1e-20, epsrel=1e-11, limit=200)[0]
                    for lo, hi in zip(breaks[:-1], breaks[1:]))
        per[i] += (value + model.p_fa * (f1 - f0)) * length / model.metres_per_scan
    return per


def model(swerling=1, rcs='constant', values=(1.0,), **kw):
    return DetectionModel(p_fa=P_FA, swerling=swerling, rcs_kind=rcs, rcs_values=values,
                          **kw)


MODELS = [(s, kind, vals) for s in (0, 1)
          for kind, vals in (('constant', (2.0,)), ('ellipsoid', ELLIPSOID))]
MODEL_IDS = [f'swerling{s}-{k}' for s, k, _ in MODELS]

# A 3-D path through a field of strong radars (SNR 1..1e4 along it), non-level segments.
PATH = np.array([[0.0, 0.0, 10.0], [40.0, 10.0, 25.0], [80.0, -5.0, 20.0],
                 [120.0, 20.0, 20.0], [160.0, 0.0, 5.0]])
THREATS = np.array([[30.0, 25.0, 0.0], [75.0, -20.0, 10.0], [110.0, 35.0, 30.0],
                    [150.0, -10.0, 0.0], [60.0, 5.0, 60.0]])
F = np.array([3e7, 1e8, 5e6, 2e8, 4e7])


# ---------------------------------------------------------------------- P_d per scan


SNRS = np.concatenate([[0.0], np.logspace(-10, 4, 141), [3e4, 1e6, 1e300]])


@pytest.mark.parametrize('p_fa', [1e-2, 1e-6, 1e-10])
def test_swerling0_matches_ncx2_over_a_wide_snr_range(p_fa):
    got, _ = p_detect_scan(SNRS, p_fa, 0)
    x = -2.0 * math.log(p_fa)
    want = stats.ncx2.sf(x, 2, 2.0 * SNRS[:-1])
    np.testing.assert_allclose(got[:-1], want, rtol=1e-12, atol=0)
    assert got[-1] == 1.0


@pytest.mark.parametrize('snr_value', [0.0, 1e-6, 0.3, 3.0, 14.0, 25.0, 60.0])
@pytest.mark.parametrize('p_fa', [1e-3, 1e-6])
def test_swerling0_matches_an_independent_marcum_q1(snr_value, p_fa):
    got = float(p_detect_scan(np.array([snr_value]), p_fa, 0)[0][0])
    want = marcum_q1(math.sqrt(2.0 * snr_value), math.sqrt(-2.0 * math.log(p_fa)))
    assert got == pytest.approx(want, rel=1e-9, abs=1e-15)
    if want > 0.5:
        # Near 1 the miss probability 1 - P_d must be right too, not only P_d.
        assert 1.0 - got == pytest.approx(1.0 - want, rel=1e-6, abs=1e-15)


@pytest.mark.parametrize('p_fa', [1e-2, 1e-6, 1e-10])
def test_swerling1_matches_the_closed_form(p_fa):
    got, _ = p_detect_scan(SNRS, p_fa, 1)
    want = np.array([math.exp(math.log(p_fa) / (1.0 + s)) for s in SNRS[:-1]])
    np.testing.assert_allclose(got[:-1], want, rtol=1e-13, atol=0)
    assert got[-1] == pytest.approx(1.0, abs=1e-15)
    assert p_detect_scan(np.array([np.inf]), p_fa, 1)[0][0] == 1.0


@pytest.mark.parametrize('swerling', [0, 1])
def test_limits_snr_zero_is_p_fa_and_snr_infinite_is_one(swerling):
    for p_fa in (0.1, 1e-6, 1e-12):
        p, _ = p_detect_scan(np.array([0.0, 1e-14, 1e10, np.inf]), p_fa, swerling)
        assert p[0] == pytest.approx(p_fa, rel=1e-12)
        assert p[1] == pytest.approx(p_fa, rel=1e-10)
        # Swerling 1 misses with probability ~ -ln P_fa / SNR; Swerling 0 never, there.
        assert 1.0 - p[2] == pytest.approx(-math.log(p_fa) / 1e10 if swerling else 0.0,
                                           rel=1e-4, abs=1e-16)
        assert p[3] == 1.0
        # Monotone in SNR.
        q, _ = p_detect_scan(SNRS, p_fa, swerling)
        assert np.all(np.diff(q) >= -1e-16)


@pytest.mark.parametrize('swerling', [0, 1])
@pytest.mark.parametrize('p_fa', [1e-3, 1e-6])
def test_dpd_dsnr_matches_finite_differences(swerling, p_fa):
    s = np.concatenate([np.logspace(-6, 2.5, 40), [1e-13]])
    _, dp = p_detect_scan(s, p_fa, swerling, want_grad=True)
    h = 1e-5 * np.maximum(s, 1e-3)
    lo = np.maximum(s - h, 0.0)
    hi = s + h
    fd = (p_detect_scan(hi, p_fa, swerling)[0] - p_detect_scan(lo, p_fa, swerling)[0]) \
        / (hi - lo)
    np.testing.assert_allclose(dp, fd, rtol=2e-5, atol=1e-13)
    # dP_d/dSNR at SNR -> 0: Swerling 0 P_fa x / 2, Swerling 1 -P_fa ln P_fa.
    d0 = p_detect_scan(np.array([0.0]), p_fa, swerling, want_grad=True)[1][0]
    want0 = -p_fa * math.log(p_fa)
    assert d0 == pytest.approx(want0, rel=1e-10)


# ------------------------------------------------------------------------------- RCS


def _sigma(m, nose, q_minus_p):
    g = np.asarray(q_minus_p, float)[None]
    return float(m.rcs(np.asarray(nose, float)[None], g / np.linalg.norm(g))[0])


def _random_units(n, seed):
    u = np.random.default_rng(seed).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1)[:, None]


def test_sphere_is_pi_r_squared_from_every_aspect():
    r = 1.7
    m = model(rcs='ellipsoid', values=(r, r, r))
    noses = _random_units(200, 1)
    sights = _random_units(200, 2)
    np.testing.assert_allclose(m.rcs(noses, sights), math.pi * r * r, rtol=1e-13)
    assert m.largest_rcs == pytest.approx(math.pi * r * r)


HEADINGS = [0.0, 30.0, 90.0, 137.0, 180.0, 270.0]


@pytest.mark.parametrize('heading_deg', HEADINGS)
def test_ellipsoid_axis_views_and_body_frame_conventions(heading_deg):
    """Level flight at any heading (the scene yawed: same sigma from the same aspect)."""
    a, b, c = ELLIPSOID
    m = model(rcs='ellipsoid', values=ELLIPSOID)
    h = math.radians(heading_deg)
    nose = np.array([math.cos(h), math.sin(h), 0.0])
    # Right of the heading with z up: heading x up = (sin h, -cos h, 0); at h = 0 (+x) it
    # is -y; at h = 90 (+y) it is +x.
    right = np.array([math.sin(h), -math.cos(h), 0.0])
    nose_view = math.pi * b * b * c * c / a ** 2
    wing_view = math.pi * a * a * c * c / b ** 2
    down_view = math.pi * a * a * b * b / c ** 2
    for sight, want in ((nose, nose_view), (-nose, nose_view), (right, wing_view),
                        (-right, wing_view), (-UP, down_view), (UP, down_view)):
        assert _sigma(m, nose, 100.0 * sight) == pytest.approx(want, rel=1e-12)
    # Scale of the segment does not matter, only its direction.
    assert _sigma(m, 7.5 * nose, -right) == pytest.approx(wing_view, rel=1e-12)


def test_body_frame_of_a_uav_flying_plus_x():
    a, b, c = ELLIPSOID
    m = model(rcs='ellipsoid', values=ELLIPSOID)
    nose = [1.0, 0.0, 0.0]
    # Radar directly below: the belly.
    assert _sigma(m, nose, [0, 0, -50]) == pytest.approx(math.pi * a * a * b * b / c ** 2)
    # Radar at -y (the right of a UAV flying +x, z up): the wing view.
    assert _sigma(m, nose, [0, -50, 0]) == pytest.approx(math.pi * a * a * c * c / b ** 2)
    # Flying +y, the radar at +x is on the right.
    assert _sigma(m, [0, 1, 0], [50, 0, 0]) == pytest.approx(math.pi * a * a * c * c / b ** 2)
    # The three views differ, so a swapped axis would fail above.
    assert len({round(v, 9) for v in (a * a * b * b / c ** 2, a * a * c * c / b ** 2,
                                       b * b * c * c / a ** 2)}) == 3


@pytest.mark.parametrize('swerling,kind,values', MODELS, ids=MODEL_IDS)
def test_rcs_and_snr_match_an_explicit_body_frame(swerling, kind, values):
    m = model(swerling, kind, values)
    rng = np.random.default_rng(7)
    n = 300
    e = rng.normal(size=(n, 3)) * [1.0, 1.0, 0.6]          # climbing and diving segments
    p = rng.uniform(-50, 50, size=(n, 3))
    q = rng.uniform(-50, 50, size=(n, 3))
    f = 10 ** rng.uniform(3, 9, size=n)
    g = q - p
    want_sigma = np.array([ref_sigma(e[k], p[k], q[k], m) for k in range(n)])
    want_snr = np.array([ref_snr(e[k], p[k], q[k], f[k], m) for k in range(n)])
    unit = g / np.linalg.norm(g, axis=1)[:, None]
    np.testing.assert_allclose(m.rcs(e, unit), want_sigma, rtol=1e-11)
    got, _, _ = snr(m, f, e, g)
    np.testing.assert_allclose(got, want_snr, rtol=1e-11)
    if kind == 'ellipsoid':
        assert want_sigma.max() <= m.largest_rcs * (1 + 1e-12)


def test_yawed_scene_has_the_same_snr():
    """Rotating path and threats about the vertical leaves every SNR and H unchanged."""
    m = model(1, 'ellipsoid', ELLIPSOID)
    angle = math.radians(71.0)
    rot = np.array([[math.cos(angle), -math.sin(angle), 0.0],
                    [math.sin(angle), math.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    h0 = path_hazard(PATH, THREATS, F, m)
    h1 = path_hazard(PATH @ rot.T, THREATS @ rot.T, F, m)
    np.testing.assert_allclose(h1.per_threat, h0.per_threat, rtol=1e-9)


# ----------------------------------------------------------------------------- hazard


@pytest.mark.parametrize('swerling,kind,values', MODELS, ids=MODEL_IDS)
def test_path_hazard_matches_quad(swerling, kind, values):
    m = model(swerling, kind, values)
    got = path_hazard(PATH, THREATS, F, m)
    want = ref_hazard(PATH, THREATS, F, m)
    np.testing.assert_allclose(got.per_threat, want, rtol=1e-8)
    assert got.hazard == pytest.approx(want.sum(), rel=1e-8)
    # The field is strong enough that the excess, not the floor, is H.
    floor = P_FA * np.linalg.norm(np.diff(PATH, axis=0), axis=1).sum() / m.metres_per_scan
    assert got.hazard > 1e3 * floor * len(F)


@pytest.mark.parametrize('swerling,kind,values', MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize('miss', [0.0, 1e-6, 0.05, 1.0])
def test_path_hazard_near_and_through_a_threat(swerling, kind, values, miss):
    m = model(swerling, kind, values)
    q = np.array([[50.0, 0.0, 20.0], [20.0, 30.0, 20.0]])
    f = np.array([1e3, 1e6])             # a weak radar (range ~6 m) passed at `miss` m
    pts = np.array([[0.0, -miss, 20.0], [100.0, -miss, 20.0], [130.0, 40.0, 35.0]])
    got = path_hazard(pts, q, f, m)
    want = ref_hazard(pts, q, f, m)
    np.testing.assert_allclose(got.per_threat, want, rtol=1e-8)
    assert np.all(np.isfinite(got.per_threat))


@pytest.mark.parametrize('swerling,kind,values', MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize('miss', [0.0, 0.5, 3.0])
def test_path_hazard_of_a_long_segment_passing_a_weak_radar(swerling, kind, values, miss,
                                                             request):
    """A 10 km segment 0-3 m from a radar of range ~5-18 m: more pieces than MAX_PIECES.

    The layout spreads at most 256 pieces evenly over the 10 km (39 m each against a
    radar range of ~5 m) and path_hazard stops doubling at 64, not converged. Splitting
    the pair into 8 sub-pieces (the `pieces` argument) gives H to 6e-13.
    """
    if swerling == 0 and kind == 'ellipsoid' and miss < 1.0:
        request.applymarker(pytest.mark.xfail(strict=True, reason=(
            'known bug: path_hazard 4.0e-7 (miss 0) and 4.3e-7 (miss 0.5) high at 2af27e1, '
            '7.7e-5 at 54a4362: 256 even pieces over 10 km, doubling stopped at 64')))
    m = model(swerling, kind, values)
    pts = np.array([[-5000.0, miss, 0.0], [5000.0, miss, 0.0], [5000.0, 3000.0, 100.0]])
    q = np.array([[37.0, 0.0, 0.0], [4000.0, 2990.0, 90.0]])
    f = np.array([1e3, 1e5])
    got = path_hazard(pts, q, f, m)
    np.testing.assert_allclose(got.per_threat, ref_hazard(pts, q, f, m), rtol=1e-8)


@pytest.mark.parametrize('swerling,kind,values', MODELS, ids=MODEL_IDS)
def test_report_identities_and_masking(swerling, kind, values):
    m = model(swerling, kind, values)
    rep = path_hazard(PATH, THREATS, F, m)
    assert rep.per_threat.sum() == pytest.approx(rep.hazard, rel=1e-14)
    assert rep.p_detect == pytest.approx(1.0 - math.exp(-rep.hazard), rel=1e-14)
    d = rep.as_dict()
    assert d['H'] == rep.hazard and len(d['per_threat']) == len(F)
    # Threat 1 masked everywhere, threat 3 sees only part of segments 1 and 2.
    seg, thr, f0, f1 = [], [], [], []
    for k in range(len(PATH) - 1):
        for i in range(len(THREATS)):
            if i == 1:
                continue
            lo, hi = ((0.2, 0.7) if i == 3 and k in (1, 2) else
                      (0.0, 0.0) if i == 3 else (0.0, 1.0))
            if hi > lo:
                seg.append(k), thr.append(i), f0.append(lo), f1.append(hi)
    pieces = (np.array(seg), np.array(thr), np.array(f0), np.array(f1))
    masked = path_hazard(PATH, THREATS, F, m, pieces=pieces)
    assert masked.per_threat[1] == 0.0
    want = ref_hazard(PATH, THREATS, F, m, pieces=pieces)
    np.testing.assert_allclose(masked.per_threat, want, rtol=1e-8)
    for i in (0, 2, 4):
        assert masked.per_threat[i] == pytest.approx(rep.per_threat[i], rel=1e-9)
    assert masked.per_threat[3] < rep.per_threat[3]


@pytest.mark.parametrize('swerling,kind,values', MODELS, ids=MODEL_IDS)
def test_gradient_matches_central_differences(swerling, kind, values):
    m = model(swerling, kind, values)
    lay = layout(PATH, THREATS, F, m)
    per, grad = hazard_and_gradient(PATH, THREATS, F, m, lay)
    assert grad.shape == PATH.shape
    fd = np.zeros_like(PATH)
    h = 1e-4
    for k in range(len(PATH)):
        for j in range(3):
            up, down = PATH.copy(), PATH.copy()
            up[k, j] += h
            down[k, j] -= h
            fd[k, j] = (hazard_and_gradient(up, THREATS, F, m, lay, False)[0].sum()
                        - hazard_and_gradient(down, THREATS, F, m, lay, False)[0].sum()
                        ) / (2 * h)
    scale = np.abs(fd).max()
    assert scale > 1e-3
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-7 * scale)


def test_gradient_of_a_vertical_and_a_weak_segment():
    """A climb straight up (the wing convention's special case) and a floor-only pair."""
    m = model(1, 'ellipsoid', ELLIPSOID)
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 30.0], [40.0, 5.0, 35.0]])
    q = np.array([[10.0, 4.0, 15.0], [1e5, 0.0, 0.0]])
    f = np.array([1e7, 1.0])
    lay = layout(pts, q, f, m)
    per, grad = hazard_and_gradient(pts, q, f, m, lay)
    assert per[1] == pytest.approx(P_FA * (30.0 + math.hypot(40.0, 5.0, 5.0)) / 20.0,
                                   rel=1e-12)
    h = 1e-5
    # Not (0, 1) or (1, 1): a y move tilts the vertical segment towards y, whose wing is
    # then along x; an x move keeps it along y, the convention at vertical.
    for k, j in ((0, 0), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1), (2, 2)):
        up, down = pts.copy(), pts.copy()
        up[k, j] += h
        down[k, j] -= h
        fd = (hazard_and_gradient(up, q, f, m, lay, False)[0].sum()
              - hazard_and_gradient(down, q, f, m, lay, False)[0].sum()) / (2 * h)
        assert grad[k, j] == pytest.approx(fd, rel=1e-5, abs=1e-10)
    # At vertical the wing is along y: a radar along x from a climb sees the belly.
    a, b, c = ELLIPSOID
    assert _sigma(m, [0, 0, 1], [40, 0, 0]) == pytest.approx(math.pi * a * a * b * b / c ** 2)
    assert _sigma(m, [0, 0, 1], [0, 40, 0]) == pytest.approx(math.pi * a * a * c * c / b ** 2)
    # The body frame has no limit at vertical (the wing follows the tilt's azimuth): the
    # hazard is discontinuous there, a property of the frame.
    tilt_x, tilt_y = pts.copy(), pts.copy()
    tilt_x[1, 0] += 1e-9
    tilt_y[1, 1] += 1e-9
    hx = hazard_and_gradient(tilt_x, q, f, m, lay, False)[0].sum()
    hy = hazard_and_gradient(tilt_y, q, f, m, lay, False)[0].sum()
    assert hx == pytest.approx(per.sum(), rel=1e-8)
    assert abs(hy - hx) > 1e-3 * hx


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
