"""Verification of the detection model (issue 43, item 3) against independent references.

Every reference (detection_refs.py) is written from the issue's equations, not the code:
P_d from scipy's ncx2, a quadrature of the Rician tail (Marcum's Q_1) and the Swerling 1
closed form; the RCS from an explicit body-frame matrix; H from scipy.integrate.quad per
threat and segment and from a scan-by-scan product and Monte Carlo of detections.
"""

import math
import numpy as np
import pytest
from scipy import stats

from detection_refs import (ELLIPSOID, F, marcum_q1, model, MODEL_IDS, MODELS, P_FA, PATH,
                            ref_hazard, ref_sigma, ref_snr, THREATS, UP)
from threat_planner.core.detection.hazard import hazard_and_gradient, layout, path_hazard
from threat_planner.core.detection.model import p_detect_scan, snr


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
def test_path_hazard_of_a_long_segment_passing_a_weak_radar(swerling, kind, values, miss):
    """A 10 km segment 0-3 m from a radar of range ~5-18 m: more pieces than MAX_PIECES.

    256 even pieces over the 10 km (39 m each against a range of ~5 m) left H 4e-7 high;
    such a pair is now cut into parts with their own closest approach.
    """
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
