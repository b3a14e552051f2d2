"""Compiled (numba) hazard and gradient on a fixed layout: the optimiser's hot path.

The same sums as :func:`.hazard.hazard_and_gradient` (which stays the reference a test
compares with), one loop over the layout's pieces and one over its quadrature nodes, so an
evaluation costs what its arithmetic costs, not numpy's ~40 calls of overhead (20
threats, 40 segments, 6,500 nodes: ~1.7 ms in numpy). Swerling 0's Marcum Q_1 is the
Poisson mixture of its chi-square tails, P_d = sum_j Pois(j; SNR) P(Pois(x/2) <= j) with
x = -2 ln P_fa, and dP_d/dSNR = sum_j Pois(j; SNR) Pois(j + 1; x/2), summed where the
first factor matters; beyond sqrt(2 SNR) > sqrt(x) + ``_SURE_GAP`` P_d is 1 to double
precision. Compiled on the first detection plan of an install and cached with the rest
(:mod:`threat_planner.core._numba_cache`, which lists it among its SOURCES and its
JIT_ONLY modules: the AOT path does not import it, so the core loads no numba).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.detection.model import SURE_GAP

try:
    # numba itself, not the planner's njit: these kernels have no AOT export, so they
    # compile (once an install, ~10 s) even where the AOT module stands in for the rest.
    from threat_planner.core import _numba_cache
    _numba_cache.import_numba()
    _numba_cache.configure()
    from numba import njit
except ImportError:  # pragma: no cover - numba is in install_requires
    def njit(*args, **kwargs):  # noqa: D103
        if args and callable(args[0]):
            return args[0]
        return lambda fn: fn

__all__ = ['compiled_hazard', 'swerling0']

#: sqrt(2 SNR) - sqrt(-2 ln P_fa) beyond which Q_1 = 1 (the model's SURE_GAP).
_SURE_GAP = SURE_GAP


@njit(cache=True)
def swerling0(s, half_x):
    """(P_d, dP_d/dSNR) of a steady target at SNR s, half_x = -ln P_fa."""
    if not s < 1e300:
        return 1.0, 0.0
    a = math.sqrt(2.0 * s)
    if a > math.sqrt(2.0 * half_x) + _SURE_GAP:
        return 1.0, 0.0
    spread = 12.0 * math.sqrt(s) + 12.0
    lo = max(0, int(s - spread))
    hi = int(s + spread) + 1
    # Poisson(half_x) terms q_j and their running sum F(j), from j = 0.
    q = math.exp(-half_x)
    cum = q
    for j in range(1, lo + 1):
        q *= half_x / j
        cum += q
    # Poisson(s) at lo, in logs (e^-s underflows for big s), then upwards.
    p = math.exp(-s + (lo * math.log(s) if lo > 0 else 0.0) - math.lgamma(lo + 1.0))
    value = 0.0
    slope = 0.0
    for j in range(lo, hi + 1):
        q_next = q * half_x / (j + 1)
        value += p * cum
        slope += p * q_next
        q = q_next
        cum += q_next
        p *= s / (j + 1)
    return min(value, 1.0), slope


@njit(cache=True)
def _form(ex, ey, ez, gx, gy, gz, aa, bb, cc, grad, out):
    """Q = g^T M(e) g; with grad, dQ/dg into out[0:3] and dQ/de into out[3:6]."""
    gg = gx * gx + gy * gy + gz * gz
    if aa == bb and bb == cc:
        if grad:
            out[0], out[1], out[2] = 2.0 * aa * gx, 2.0 * aa * gy, 2.0 * aa * gz
            out[3] = out[4] = out[5] = 0.0
        return aa * gg
    ee = ex * ex + ey * ey + ez * ez
    eg = ex * gx + ey * gy + ez * gz
    h2 = ex * ex + ey * ey
    vertical = h2 <= 1e-24 * ee
    if vertical:
        h2 = 1.0
        wing = gy
    else:
        wing = ey * gx - ex * gy
    q = cc * gg + (aa - cc) * eg * eg / ee + (bb - cc) * wing * wing / h2
    if grad:
        c1 = 2.0 * (aa - cc) * eg / ee
        c2 = 2.0 * (bb - cc) * wing / h2
        if vertical:
            out[0] = 2.0 * cc * gx + c1 * ex
            out[1] = 2.0 * cc * gy + c1 * ey + c2
            out[2] = 2.0 * cc * gz + c1 * ez
        else:
            out[0] = 2.0 * cc * gx + c1 * ex + c2 * ey
            out[1] = 2.0 * cc * gy + c1 * ey - c2 * ex
            out[2] = 2.0 * cc * gz + c1 * ez
        r = eg / ee
        out[3] = c1 * (gx - r * ex)
        out[4] = c1 * (gy - r * ey)
        out[5] = c1 * (gz - r * ez)
        if not vertical:
            c3 = (bb - cc) * wing * wing / (h2 * h2)
            out[3] += c2 * (-gy) - c3 * 2.0 * ex
            out[4] += c2 * gx - c3 * 2.0 * ey
    return q


@njit(cache=True)
def _hazard(points, positions, f, pair_seg, pair_thr, pair_span, node_piece, node_t, node_w,
            k_rcs, aa, bb, cc, p_fa, swerling, vt, grad_on, per, grad):
    nseg = points.shape[0] - 1
    length = np.empty(nseg)
    unit = np.empty((nseg, 3))
    for s in range(nseg):
        dx = points[s + 1, 0] - points[s, 0]
        dy = points[s + 1, 1] - points[s, 1]
        dz = points[s + 1, 2] - points[s, 2]
        ln = math.sqrt(dx * dx + dy * dy + dz * dz)
        length[s] = ln
        inv = 1.0 / ln if ln > 0.0 else 0.0
        unit[s, 0], unit[s, 1], unit[s, 2] = dx * inv, dy * inv, dz * inv
    per[:] = 0.0
    if grad_on:
        grad[:, :] = 0.0
    for k in range(pair_seg.shape[0]):
        s = pair_seg[k]
        per[pair_thr[k]] += p_fa * pair_span[k] * length[s] / vt
        if grad_on:
            c = p_fa * pair_span[k] / vt
            for d in range(3):
                grad[s, d] -= c * unit[s, d]
                grad[s + 1, d] += c * unit[s, d]
    half_x = -math.log(p_fa)
    buf = np.empty(6)
    for m in range(node_t.shape[0]):
        piece = node_piece[m]
        s = pair_seg[piece]
        if length[s] <= 0.0:
            continue    # a folded segment: no length, no hazard, no gradient
        i = pair_thr[piece]
        t = node_t[m]
        ex = points[s + 1, 0] - points[s, 0]
        ey = points[s + 1, 1] - points[s, 1]
        ez = points[s + 1, 2] - points[s, 2]
        gx = positions[i, 0] - (points[s, 0] + t * ex)
        gy = positions[i, 1] - (points[s, 1] + t * ey)
        gz = positions[i, 2] - (points[s, 2] + t * ez)
        q = _form(ex, ey, ez, gx, gy, gz, aa, bb, cc, grad_on, buf)
        snr = f[i] * k_rcs / (q * q) if q > 0.0 else math.inf
        if swerling == 1:
            inv = 1.0 / (1.0 + snr) if snr < math.inf else 0.0
            excess = p_fa * math.expm1(half_x * (snr * inv if snr < math.inf else 1.0))
            dp = half_x * (excess + p_fa) * inv * inv
        else:
            pd, dp = swerling0(snr, half_x)
            excess = pd - p_fa
        wl = node_w[m] * length[s] / vt
        per[i] += wl * excess
        if grad_on and q > 0.0 and snr < math.inf:
            c = wl * dp * (-2.0 * snr / q)
            cl = node_w[m] * excess / vt
            for d in range(3):
                g_g = c * buf[d]
                g_e = c * buf[3 + d] + cl * unit[s, d]
                grad[s, d] += -(1.0 - t) * g_g - g_e
                grad[s + 1, d] += -t * g_g + g_e


def compiled_hazard(points: NDArray, positions: NDArray, intensities: NDArray, model,
                    lay, want_grad: bool = True) -> tuple[NDArray, NDArray | None]:
    """:func:`.hazard.hazard_and_gradient`'s (per-threat H, dH/dpoints), compiled."""
    points = np.ascontiguousarray(points, float)
    per = np.zeros(len(positions))
    grad = np.zeros_like(points)
    aa, bb, cc = model.axes_squared
    _hazard(points, np.ascontiguousarray(positions, float),
            np.ascontiguousarray(intensities, float), _ints(lay.seg), _ints(lay.thr),
            np.ascontiguousarray(lay.f1 - lay.f0, float), _ints(lay.node_piece),
            np.ascontiguousarray(lay.node_t, float), np.ascontiguousarray(lay.node_w, float),
            float(model.rcs_constant), float(aa),
            float(bb), float(cc), float(model.p_fa), int(model.swerling),
            float(model.metres_per_scan), bool(want_grad), per, grad)
    return per, (grad if want_grad else None)


def _ints(a: NDArray) -> NDArray:
    return np.ascontiguousarray(a, np.int64)
