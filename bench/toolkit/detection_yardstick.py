"""Issue 43's detection model written again for ``python -m bench detection``, and its yardsticks.

No ``threat_planner.core.detection`` code: the model from the issue's text.

* :func:`independent_hazard`: the whole model (SNR = F sigma / r^4, sigma from the
  issue's body frame, nose along the segment and right wing horizontal; Swerling 1 in
  closed form, Swerling 0 from scipy's ``ncx2.sf``), by composite Simpson at a fixed
  step [m]: the check of the product's H on every RCS and Swerling case.
* :func:`hazard`: constant RCS and Swerling 1 with its exact gradient (of the Simpson
  sum at ``intervals`` a segment), which the yardsticks minimise and grade with.
* :func:`yardstick` and :func:`bounded_yardstick`: multi-start SLSQP on w H + (1 - w) L /
  L_0, or on L / L_0 under H <= -ln(1 - P), under the product's smooth limit rows
  (``constraint_values_jacobian``), every result graded with the bench's own
  ``check_limits`` and the box.

Terrain masking is not modelled (the fresh fields have none).
"""

from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.stats import ncx2

from bench.toolkit.flight_limits import check_limits, Limits
from bench.toolkit.yardstick import resample

__all__ = ['bounded_yardstick', 'feasible', 'hazard', 'independent_hazard', 'length',
           'objective', 'p_d', 'p_detect', 'resample', 'sigma', 'yardstick']


def p_d(snr: NDArray, p_fa: float, swerling: int) -> NDArray:
    """P_d per scan: Swerling 1 P_fa^(1/(1+SNR)), Swerling 0 ncx2.sf(-2 ln P_fa, 2, 2 SNR)."""
    snr = np.asarray(snr, float)
    if swerling == 1:
        return p_fa ** (1.0 / (1.0 + snr))
    return ncx2.sf(-2.0 * math.log(p_fa), 2.0, 2.0 * snr)


def sigma(nose: NDArray, los: NDArray, rcs: dict) -> NDArray:
    """RCS [m^2] along unit lines of sight ``los`` (K, 3) from a segment of unit direction nose."""
    if 'constant' in rcs:
        return np.full(len(los), float(rcs['constant']))
    a, b, c = (float(x) for x in rcs['ellipsoid'])
    h = math.hypot(nose[0], nose[1])
    wing = np.array([nose[1] / h, -nose[0] / h, 0.0]) if h > 1e-12 else np.array([1.0, 0, 0])
    ux2 = (los @ nose) ** 2
    uy2 = (los @ wing) ** 2
    uz2 = np.clip(1.0 - ux2 - uy2, 0.0, None)
    return math.pi * (a * b * c) ** 2 / (a * a * ux2 + b * b * uy2 + c * c * uz2) ** 2


def independent_hazard(points: NDArray, positions: NDArray, intensities: NDArray,
                       speed: float = 20.0, scan_period: float = 1.0, p_fa: float = 1e-6,
                       swerling: int = 1, rcs: dict | None = None, step: float = 0.05
                       ) -> tuple[float, float, NDArray]:
    """Return ``(P_detect, H, per_threat)`` by composite Simpson at spacing <= ``step`` [m]."""
    rcs = rcs or {'constant': 1.0}
    p = np.asarray(points, float)
    q = np.asarray(positions, float).reshape(-1, 3)
    f = np.asarray(intensities, float)
    per = np.zeros(len(q))
    for a, b in zip(p[:-1], p[1:]):
        length = float(np.linalg.norm(b - a))
        if length == 0.0:
            continue
        nose = (b - a) / length
        m = max(2, 2 * math.ceil(length / step / 2))
        t = np.linspace(0.0, 1.0, m + 1)
        wts = np.ones(m + 1)
        wts[1:-1:2], wts[2:-1:2] = 4.0, 2.0
        wts *= length / m / 3.0
        x = a + t[:, None] * (b - a)
        for i in range(len(q)):
            g = q[i] - x
            r2 = np.einsum('ij,ij->i', g, g)
            los = g / np.sqrt(r2)[:, None]
            snr = f[i] * sigma(nose, los, rcs) / r2 ** 2
            per[i] += float(wts @ p_d(snr, p_fa, swerling))
    per /= speed * scan_period
    h = float(per.sum())
    return -math.expm1(-h), h, per


OPT_INTERVALS = 32
EVAL_INTERVALS = 256


def simpson(intervals: int) -> tuple[NDArray, NDArray]:
    """Nodes in [0, 1] and weights (sum 1) of composite Simpson."""
    t = np.linspace(0.0, 1.0, intervals + 1)
    w = np.ones(intervals + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return t, w / (3.0 * intervals)


def hazard(points, positions, intensities, *, speed=20.0, scan_period=1.0, p_fa=1e-6,
           rcs=1.0, intervals=EVAL_INTERVALS, want_grad=False):
    """H of a polyline, or (H, dH/dpoints) with ``want_grad``."""
    p = np.asarray(points, float)
    q = np.asarray(positions, float)
    f = np.asarray(intensities, float) * rcs
    t, wt = simpson(intervals)
    a, d = p[:-1], np.diff(p, axis=0)
    ell = np.linalg.norm(d, axis=1)
    x = a[:, None, :] + t[None, :, None] * d[:, None, :]
    r = x[:, :, None, :] - q[None, None, :, :]
    rho2 = np.einsum('skni,skni->skn', r, r)
    s = f[None, None, :] / (rho2 * rho2)
    lnp = math.log(p_fa)
    pd = np.exp(lnp / (1.0 + s))
    scale = 1.0 / (speed * scan_period)
    avg = np.einsum('k,skn->sn', wt, pd)
    total = float(scale * (ell[:, None] * avg).sum())
    if not want_grad:
        return total
    dpds = pd * (-lnp) / (1.0 + s) ** 2
    gx = ((dpds * (-4.0 * s / rho2))[..., None] * r).sum(axis=2)
    wk = wt[None, :, None]
    ga = scale * ell[:, None] * np.sum(wk * (1.0 - t)[None, :, None] * gx, axis=1)
    gb = scale * ell[:, None] * np.sum(wk * t[None, :, None] * gx, axis=1)
    u = d / np.maximum(ell, 1e-300)[:, None]
    mean_s = scale * avg.sum(axis=1)
    ga -= mean_s[:, None] * u
    gb += mean_s[:, None] * u
    grad = np.zeros_like(p)
    grad[:-1] += ga
    grad[1:] += gb
    return total, grad


def p_detect(points, positions, intensities, **kw) -> float:
    return -math.expm1(-hazard(points, positions, intensities, **kw))


def length(points) -> float:
    return float(np.linalg.norm(np.diff(np.asarray(points, float), axis=0), axis=1).sum())


def objective(points, positions, intensities, w, **kw) -> float:
    p = np.asarray(points, float)
    l0 = float(np.linalg.norm(p[-1] - p[0]))
    return w * hazard(p, positions, intensities, **kw) + (1.0 - w) * length(p) / l0


def feasible(points, lo, hi, limits: dict) -> bool:
    p = np.asarray(points, float)
    lim = Limits(limits['max_climb_deg'], limits['max_dive_deg'], limits['min_turn_radius_m'])
    return bool(np.all(np.isfinite(p)) and check_limits(p, lim)
                and np.all(p >= np.asarray(lo) - 1e-9) and np.all(p <= np.asarray(hi) + 1e-9))


def _len_grad(p):
    d = np.diff(p, axis=0)
    ell = np.linalg.norm(d, axis=1)
    u = d / np.maximum(ell, 1e-300)[:, None]
    gl = np.zeros_like(p)
    gl[:-1] -= u
    gl[1:] += u
    return ell.sum(), gl


def _run(starts, fun, extra, lo, hi, limits, n_segments, maxiter, grade) -> dict:
    from threat_planner.core.optimise.limits import constraint_values_jacobian, FlightLimits
    fl = FlightLimits(limits['max_climb_deg'], limits['max_dive_deg'],
                      limits['min_turn_radius_m'], limits.get('min_altitude_m', 0.0))
    best, report, t0 = None, [], time.perf_counter()
    for how, path in starts:
        p0 = resample(path, n_segments)
        s, g = p0[0].copy(), p0[-1].copy()
        p0[1:-1] = np.clip(p0[1:-1], lo, hi)

        def pts(z):
            return np.vstack([s, z.reshape(-1, 3), g])

        def lim(z):
            gv, jac = constraint_values_jacobian(pts(z), fl)
            return gv, jac[:, 1:-1, :].reshape(len(gv), -1)
        cons = [{'type': 'ineq', 'fun': lambda z: lim(z)[0], 'jac': lambda z: lim(z)[1]}]
        cons += [{'type': 'ineq', 'fun': (lambda z, c=c: c(pts(z))[0]),
                  'jac': (lambda z, c=c: c(pts(z))[1][1:-1].ravel()[None, :])} for c in extra]
        bounds = list(zip(np.tile(lo, n_segments - 1), np.tile(hi, n_segments - 1)))
        try:
            res = minimize(lambda z: fun(pts(z)), p0[1:-1].ravel(), jac=True, method='SLSQP',
                           bounds=bounds, constraints=cons,
                           options={'maxiter': maxiter, 'ftol': 1e-12})
            p, msg = pts(res.x), str(res.message)
        except (ValueError, np.linalg.LinAlgError) as exc:
            p, msg = p0, f'SLSQP error: {exc}'
        ok, value = grade(p)
        report.append({'how': how, 'value': value, 'feasible': ok, 'message': msg})
        if ok and (best is None or value < best['value']):
            best = {'value': value, 'path': p, 'how': how}
    if best is None:
        best = {'value': math.inf, 'path': None, 'how': 'none feasible'}
    return {**best, 'feasible': best['path'] is not None, 'starts': report,
            'seconds': time.perf_counter() - t0}


def yardstick(positions, intensities, lo, hi, w, limits, starts: Sequence, n_segments=40,
              maxiter=300, **model) -> dict:
    """Least w H + (1 - w) L / L_0 by SLSQP from each start under the limits."""
    first = np.asarray(starts[0][1], float)
    l0 = float(np.linalg.norm(first[-1] - first[0]))

    def fun(p):
        h, gh = hazard(p, positions, intensities, intervals=OPT_INTERVALS, want_grad=True,
                       **model)
        L, gl = _len_grad(p)
        return w * h + (1 - w) * L / l0, (w * gh + (1 - w) * gl / l0)[1:-1].ravel()

    def grade(p):
        return feasible(p, lo, hi, limits), objective(p, positions, intensities, w, **model)
    return _run(starts, fun, [], lo, hi, limits, n_segments, maxiter, grade)


def bounded_yardstick(positions, intensities, lo, hi, p_max, limits, starts: Sequence,
                      n_segments=40, maxiter=300, **model) -> dict:
    """Shortest L / L_0 with H <= -ln(1 - p_max) by SLSQP from each start."""
    first = np.asarray(starts[0][1], float)
    l0 = float(np.linalg.norm(first[-1] - first[0]))
    h_max = -math.log1p(-p_max)

    def fun(p):
        L, gl = _len_grad(p)
        return L / l0, gl[1:-1].ravel() / l0

    def bound(p):
        h, gh = hazard(p, positions, intensities, intervals=OPT_INTERVALS, want_grad=True,
                       **model)
        return np.array([(h_max * (1 - 1e-6) - h) / h_max]), -gh / h_max

    def grade(p):
        h = hazard(p, positions, intensities, **model)
        return (feasible(p, lo, hi, limits) and h <= h_max * (1 + 1e-9)), length(p) / l0
    out = _run(starts, fun, [bound], lo, hi, limits, n_segments, maxiter, grade)
    out['h_max'] = h_max
    return out
