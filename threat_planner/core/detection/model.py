"""The radar model of issue 43: SNR with an aspect-dependent RCS, and Swerling P_d per scan.

SNR of threat i at UAV position p (the radar equation with the paper's F as the SNR
constant of a 1 m^2 target)::

    SNR_i = F_i sigma / (sigma_ref |p - q_i|^4),   sigma_ref = 1 m^2

with sigma the RCS seen from the radar. In the body frame (nose along the segment flown,
right wing horizontal, down completing the frame), with u the unit line of sight from the
UAV to the radar, an ellipsoid of semi-axes a, b, c (nose, right wing, down) has
sigma = pi a^2 b^2 c^2 / (a^2 u_x^2 + b^2 u_y^2 + c^2 u_z^2)^2. Writing g = q - p and
M = a^2 n n^T + b^2 r r^T + c^2 d d^T (the body axes n, r, d), that is
SNR = F pi a^2 b^2 c^2 / (g^T M g)^2: a quadratic form of g, smooth in p and in the
segment's direction, which is how :func:`snr` computes it and its gradients.
A constant RCS s is M = I and F s / |g|^4.

P_d per scan: Swerling 1, P_fa^(1 / (1 + SNR)); Swerling 0, Marcum's
Q_1(sqrt(2 SNR), sqrt(-2 ln P_fa)) = ncx2.sf(-2 ln P_fa, 2, 2 SNR).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.inputs.rcs import parse_rcs
from threat_planner.errors import InputError

__all__ = ['DetectionModel', 'p_detect_scan', 'snr', 'SURE_GAP']

#: sqrt(2 SNR) - sqrt(-2 ln P_fa) beyond which a steady target's P_d is 1 (1 - Q_1 below
#: 1e-17: the Rician tail beyond 9 standard deviations).
SURE_GAP = 9.0


@dataclass(frozen=True)
class DetectionModel:
    """What detection depends on besides the threats.

    Attributes
    ----------
    speed_mps : float
        Speed the path is flown at [m/s].
    scan_period_s : float
        Radar scan period T [s].
    p_fa : float
        False-alarm probability per scan, 0 < p_fa < 1.
    swerling : int
        0 (steady target) or 1 (scan-to-scan fluctuation).
    rcs_kind : str
        ``'constant'`` or ``'ellipsoid'``.
    rcs_values : tuple of float
        ``(s,)`` [m^2] or the semi-axes ``(a, b, c)`` [m] along nose, right wing, down.

    """

    speed_mps: float = 20.0
    scan_period_s: float = 1.0
    p_fa: float = 1.0e-6
    swerling: int = 1
    rcs_kind: str = 'constant'
    rcs_values: tuple = (1.0,)

    def __post_init__(self) -> None:
        for name in ('speed_mps', 'scan_period_s'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f'{name}: must be finite and > 0, got {value!r}')
        if not (0.0 < self.p_fa < 1.0):
            raise InputError(f'p_fa: must satisfy 0 < p_fa < 1, got {self.p_fa!r}')
        if self.swerling not in (0, 1) or isinstance(self.swerling, bool):
            raise InputError(f'swerling: must be 0 or 1, got {self.swerling!r}')
        kind, values = parse_rcs({self.rcs_kind: list(self.rcs_values)})
        object.__setattr__(self, 'rcs_values', values)

    @classmethod
    def of(cls, config: object) -> 'DetectionModel':
        """Return the model of a PlannerConfig (``speed_mps``, ``scan_period_s``, ...)."""
        kind, values = parse_rcs(getattr(config, 'rcs'))
        return cls(speed_mps=float(config.speed_mps),
                   scan_period_s=float(config.scan_period_s), p_fa=float(config.p_fa),
                   swerling=int(config.swerling), rcs_kind=kind, rcs_values=values)

    @property
    def metres_per_scan(self) -> float:
        """Distance flown in one scan, v T [m]: the hazard's unit length."""
        return self.speed_mps * self.scan_period_s

    @property
    def rcs_constant(self) -> float:
        """K of SNR = F K / (g^T M g)^2 [m^2 for a constant RCS; m^6 for an ellipsoid]."""
        if self.rcs_kind == 'constant':
            return float(self.rcs_values[0])
        a, b, c = self.rcs_values
        return math.pi * (a * b * c) ** 2

    @property
    def axes_squared(self) -> tuple[float, float, float]:
        """(a^2, b^2, c^2) of M [m^2]; (1, 1, 1) for a constant RCS."""
        if self.rcs_kind == 'constant':
            return 1.0, 1.0, 1.0
        a, b, c = self.rcs_values
        return a * a, b * b, c * c

    @property
    def largest_rcs(self) -> float:
        """Largest sigma from any aspect [m^2] (screening far threats)."""
        if self.rcs_kind == 'constant':
            return float(self.rcs_values[0])
        a, b, c = self.rcs_values
        return math.pi * (a * b * c) ** 2 / min(a, b, c) ** 4

    @property
    def smallest_rcs(self) -> float:
        """Smallest sigma from any aspect [m^2] (inside its range P_d is flat)."""
        if self.rcs_kind == 'constant':
            return float(self.rcs_values[0])
        a, b, c = self.rcs_values
        return math.pi * (a * b * c) ** 2 / max(a, b, c) ** 4

    def rcs(self, nose: NDArray, line_of_sight: NDArray) -> NDArray:
        """Return sigma [m^2] seen along unit lines of sight (N, 3) from segments along `nose`."""
        g = np.asarray(line_of_sight, float)
        q = self._form(np.asarray(nose, float), g)
        return self.rcs_constant * np.einsum('ij,ij->i', g, g) ** 2 / q ** 2

    def p_detect(self, snr_: NDArray) -> NDArray:
        """P_d per scan at each SNR (Swerling 0 or 1)."""
        return p_detect_scan(snr_, self.p_fa, self.swerling)[0]

    def _form(self, e: NDArray, g: NDArray) -> NDArray:
        return snr_parts(e, g, self.axes_squared)[0]


def snr_parts(e: NDArray, g: NDArray, axes2: tuple[float, float, float],
              want_grad: bool = False) -> tuple:
    """Q = g^T M(e) g of segment directions e and radar offsets g = q - p, (N, 3) each.

    Returns ``(Q, dQ/dg, dQ/de)``, the gradients None unless `want_grad`. The right wing is
    the horizontal unit vector across e (r = e x up / |e x up|), so r r^T needs only e's
    horizontal part; a vertical segment has its wings along y (its frame has no limit there:
    the flight limits keep paths off it).
    """
    aa, bb, cc = axes2
    gg = np.einsum('ij,ij->i', g, g)
    if aa == bb == cc:
        q = aa * gg
        return (q, 2.0 * aa * g, np.zeros_like(g)) if want_grad else (q, None, None)
    # A folded segment (e = 0) has no length to weigh its hazard: any direction will do.
    ee = np.einsum('ij,ij->i', e, e)
    e = np.where((ee > 0)[:, None], e, np.array([1.0, 0.0, 0.0]))
    ee = np.where(ee > 0, ee, 1.0)
    eg = np.einsum('ij,ij->i', e, g)
    h2 = e[:, 0] ** 2 + e[:, 1] ** 2
    vertical = h2 <= 1e-24 * ee
    h2s = np.where(vertical, 1.0, h2)
    wing = np.where(vertical, g[:, 1], (e[:, 1] * g[:, 0] - e[:, 0] * g[:, 1]))
    q = cc * gg + (aa - cc) * eg ** 2 / ee + (bb - cc) * wing ** 2 / h2s
    if not want_grad:
        return q, None, None
    across = np.stack([e[:, 1], -e[:, 0], np.zeros_like(h2)], axis=1)
    across[vertical] = (0.0, 1.0, 0.0)
    dq_dg = (2.0 * cc * g + (2.0 * (aa - cc) * eg / ee)[:, None] * e
             + (2.0 * (bb - cc) * wing / h2s)[:, None] * across)
    dq_de = (2.0 * (aa - cc) * (eg / ee)[:, None] * (g - (eg / ee)[:, None] * e))
    dw_de = np.stack([-g[:, 1], g[:, 0], np.zeros_like(h2)], axis=1)
    dh2_de = np.stack([2.0 * e[:, 0], 2.0 * e[:, 1], np.zeros_like(h2)], axis=1)
    horizontal = (bb - cc) * (2.0 * (wing / h2s)[:, None] * dw_de
                              - (wing ** 2 / h2s ** 2)[:, None] * dh2_de)
    horizontal[vertical] = 0.0
    return q, dq_dg, dq_de + horizontal


def snr(model: DetectionModel, intensities: NDArray, e: NDArray, g: NDArray,
        want_grad: bool = False) -> tuple:
    """SNR of radars of intensity F at offsets g = q - p from a UAV flying along e.

    Returns ``(SNR, dSNR/dg, dSNR/de)`` ((N,), (N, 3), (N, 3)); the gradients None unless
    `want_grad`.
    """
    q, dq_dg, dq_de = snr_parts(e, g, model.axes_squared, want_grad)
    with np.errstate(divide='ignore', over='ignore'):
        s = np.asarray(intensities, float) * model.rcs_constant / q ** 2
    if not want_grad:
        return s, None, None
    factor = np.where(q > 0, -2.0 * s / np.where(q > 0, q, 1.0), 0.0)[:, None]
    return s, factor * dq_dg, factor * dq_de


def p_detect_scan(snr_: NDArray, p_fa: float, swerling: int,
                  want_grad: bool = False) -> tuple:
    """P_d per scan and, with `want_grad`, dP_d/dSNR, at each SNR.

    Swerling 1: P_d = P_fa^(1 / (1 + SNR)). Swerling 0: Marcum's
    Q_1(sqrt(2 SNR), sqrt(-2 ln P_fa)), with dQ_1/dSNR = sqrt(x / (2 SNR)) e^(-SNR - x/2)
    I_1(sqrt(2 SNR x)) for x = -2 ln P_fa (SNR -> 0: x/2 e^(-x/2)).
    """
    s = np.asarray(snr_, float)
    log_fa = math.log(p_fa)
    if swerling == 1:
        with np.errstate(over='ignore', invalid='ignore'):
            inv = np.where(np.isinf(s), 0.0, 1.0 / (1.0 + s))
        p = np.exp(log_fa * inv)
        return (p, -log_fa * p * inv * inv) if want_grad else (p, None)
    x = -2.0 * log_fa
    # Where sqrt(2 SNR) exceeds sqrt(x) by SURE_GAP, 1 - Q_1 < 1e-17 (and ncx2.sf gives
    # NaN at SNR ~ 1e300): P_d = 1 there.
    finite = np.isfinite(s) & (np.sqrt(2.0 * np.where(np.isfinite(s), s, 0.0))
                               <= math.sqrt(x) + SURE_GAP)
    sf = np.where(finite, s, 0.0)
    p = np.where(finite, _ncx2_sf(x, sf), 1.0)
    if not want_grad:
        return p, None
    from scipy import special   # only here: importing the core loads no scipy
    z = np.sqrt(2.0 * sf * x)
    tiny = sf < 1e-12
    # e^(-SNR - x/2) I_1(z) sqrt(x / (2 SNR)), I_1 scaled (ive) against overflow; below
    # 1e-12, I_1(z) = z / 2 to double precision and the factor is x / 2.
    scaled = special.ive(1, z) * np.sqrt(x / (2.0 * np.where(tiny, 1.0, sf)))
    dp = np.where(tiny, 0.5 * x * np.exp(-sf - 0.5 * x), scaled * np.exp(z - sf - 0.5 * x))
    dp = np.where(finite, dp, 0.0)
    return p, dp


def _ncx2_sf(x: float, s: NDArray) -> NDArray:
    """ncx2.sf(x, 2, 2 s): P_d of a steady target (scipy's boost implementation)."""
    from scipy.stats import ncx2
    return ncx2.sf(x, 2.0, 2.0 * s)
