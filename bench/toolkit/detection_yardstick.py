"""Independent check of the detection hazard (issue 43) for ``python -m bench detection``.

:func:`independent_hazard` recomputes H = sum_i integral P_d,i ds / (v T) along a polyline
with its own formulas (no ``threat_planner.core.detection`` code): SNR = F sigma / r^4,
sigma from the issue's body frame (nose along the segment, right wing horizontal), P_d of
Swerling 1 in closed form and of Swerling 0 from scipy's ``ncx2.sf``, integrated per
segment by composite Simpson at a fixed step. P_detect = 1 - exp(-H). Terrain masking is
not modelled (the fresh fields have none).

Status: only this check exists so far; the multi-start SLSQP yardstick and the suite
are not written yet.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.stats import ncx2


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
