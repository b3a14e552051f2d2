"""Cumulative detection along a path: the hazard H, P_detect = 1 - exp(-H), and dH/dpoints.

H = sum over threats of the integral of P_d,i(s) ds / (v T) along the polyline, each
threat over the parts of the segments it sees (all of them without terrain masking). A
segment's body frame is fixed along it (the nose along the segment flown).

P_d tends to P_fa far from every radar, so each seen metre adds P_fa / (v T) per threat:
that floor is integrated exactly, and the excess P_d - P_fa by composite Gauss-Legendre
quadrature on pieces no longer than ``PIECE`` of the radar's closest approach (or of its
detection range, where the path passes closer). :func:`path_hazard` doubles the pieces
until H changes by less than ``TOLERANCE`` (relative): the reported H is exact to that.
:func:`hazard_and_gradient` holds one such layout fixed, so the optimiser sees a smooth
function with its exact gradient; the layout is re-made between its rounds.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core import _aot
from threat_planner.core.detection.model import DetectionModel, p_detect_scan, snr

__all__ = ['DetectionReport', 'Layout', 'hazard_and_gradient', 'layout', 'path_hazard', 'profile',
           'PIECE', 'TOLERANCE']

#: Threats from which :func:`path_hazard` sums on the compiled kernel
#: (:func:`.kernels.compiled_hazard`, the same sums up to rounding), not numpy's: where a
#: plan loads numba anyway (its edge costs go to the JIT kernels). Every plan's report
#: runs it: at 10,000 threats numpy took 1.08 s and 435 MiB of temporaries, twice the
#: plan's RSS.
COMPILED_THREATS = _aot.PARALLEL_THREATS
#: Gauss-Legendre nodes per piece.
ORDER = 8
#: Longest piece, as a fraction of the pair's closest approach (or detection range).
PIECE = 0.5
#: Most pieces of one (segment, threat) pair; a pair that needs more is cut in
#: SPLIT_PARTS, up to SPLITS times.
MAX_PIECES = 256
SPLIT_PARTS = 8
SPLITS = 8
#: A pair whose largest SNR along its segment is below this adds only the floor (its
#: excess is below 1e-12 P_fa |ln P_fa| per scan).
NEGLIGIBLE_SNR = 1e-12
#: Relative change of H at which :func:`path_hazard` stops doubling the pieces.
TOLERANCE = 1e-9
#: SNR at which a radar's range stands in for the closest approach of a pair that passes
#: closer (P_d is flat inside it).
RANGE_SNR = 1.0

#: Nodes of a short piece (no longer than SHORT of its scale), where the integrand is
#: nearly a polynomial of low degree: half the work of a full one.
SHORT_ORDER = 4
SHORT = 0.05
#: Pieces no longer than this of their scale are exact with their first layout (8 nodes
#: over at most 0.3 of the distance: an error ~ 0.15^16 of their excess).
SETTLED = 0.3
#: ... and of a piece no longer than FAR of its scale (a far radar; its 4-point error
#: there is (FAR / 2)^8 / 3e4 ~ 1e-20 of its excess, the 2-point one ~ 1e-12): a quarter.
FAR_ORDER = 2
FAR = 0.003


@lru_cache(maxsize=None)
def _rule(order: int) -> tuple[NDArray, NDArray]:
    """Return Gauss-Legendre nodes and weights on [0, 1].

    numpy.polynomial is loaded on first use: a plan that reports no detection never
    imports it.
    """
    from numpy.polynomial import legendre
    nodes, weights = legendre.leggauss(order)
    return 0.5 * (nodes + 1.0), 0.5 * weights


@dataclass(frozen=True)
class DetectionReport:
    """Cumulative detection of one path.

    Attributes
    ----------
    p_detect : float
        P_detect = 1 - exp(-H).
    hazard : float
        H, the expected number of detections.
    per_threat : ndarray
        Each threat's H_i, (N,); they sum to H.

    """

    p_detect: float
    hazard: float
    per_threat: NDArray

    def as_dict(self) -> dict:
        """JSON-ready ``{P_detect, H, per_threat}``."""
        return {'P_detect': self.p_detect, 'H': self.hazard,
                'per_threat': [float(v) for v in self.per_threat]}


@dataclass(frozen=True)
class Layout:
    """Which (segment, threat) pieces a hazard sums, and where its quadrature nodes sit.

    Attributes
    ----------
    seg, thr : ndarray of int
        Segment and threat of each seen piece.
    f0, f1 : ndarray
        The piece runs from fraction f0 to f1 of its segment.
    node_piece : ndarray of int
        Piece of each quadrature node.
    node_t, node_w : ndarray
        Each node's fraction along its segment and its weight (a fraction of the segment).

    """

    seg: NDArray
    thr: NDArray
    f0: NDArray
    f1: NDArray
    node_piece: NDArray
    node_t: NDArray
    node_w: NDArray


def _closest(a: NDArray, b: NDArray, q: NDArray) -> NDArray:
    d = b - a
    dd = np.maximum(np.einsum('ij,ij->i', d, d), 1e-300)
    t = np.clip(np.einsum('ij,ij->i', q - a, d) / dd, 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - q, axis=1)


def _pairs(points: NDArray, positions: NDArray, intensities: NDArray, model: DetectionModel,
           pieces: tuple | None) -> tuple:
    """Each seen piece's (seg, thr, f0, f1, length [m], scale [m], kept, largest SNR)."""
    points = np.asarray(points, float)
    a, b = points[:-1], points[1:]
    n_seg, n_thr = len(a), len(positions)
    if pieces is None:
        seg = np.repeat(np.arange(n_seg), n_thr)
        thr = np.tile(np.arange(n_thr), n_seg)
        f0, f1 = np.zeros(len(seg)), np.ones(len(seg))
    else:
        seg, thr, f0, f1 = (np.asarray(x) for x in pieces)
        seg, thr = seg.astype(np.int64), thr.astype(np.int64)
        f0, f1 = f0.astype(float), f1.astype(float)
    d = b - a
    for cuts in range(SPLITS + 1):
        pa, pb = a[seg] + f0[:, None] * d[seg], a[seg] + f1[:, None] * d[seg]
        near = _closest(pa, pb, positions[thr])
        # Inside the range at the smallest aspect's RCS, P_d is flat: no finer than that.
        inner = (np.asarray(intensities, float)[thr] * model.smallest_rcs / RANGE_SNR) ** 0.25
        length = np.linalg.norm(pb - pa, axis=1)
        wide = length > MAX_PIECES * PIECE * np.maximum(near, 0.25 * inner)
        if cuts == SPLITS or not wide.any():
            break
        # A pair that would need more than MAX_PIECES even pieces (a long segment beside
        # a weak radar) is cut in SPLIT_PARTS, each with its own closest approach.
        k = SPLIT_PARTS
        cut = np.repeat(np.flatnonzero(wide), k)
        step = (f1[cut] - f0[cut]) / k
        lo = f0[cut] + step * np.tile(np.arange(k), int(wide.sum()))
        keep = ~wide
        seg, thr = np.concatenate([seg[keep], seg[cut]]), np.concatenate([thr[keep], thr[cut]])
        f0, f1 = np.concatenate([f0[keep], lo]), np.concatenate([f1[keep], lo + step])
    # sigma <= largest_rcs from every aspect: SNR <= F sigma_max / d^4.
    reach = (np.asarray(intensities, float)[thr] * model.largest_rcs) ** 0.25
    with np.errstate(divide='ignore', over='ignore'):
        top = np.where(near > 0, (reach / np.maximum(near, 1e-300)) ** 4, np.inf)
    keep = (top >= NEGLIGIBLE_SNR) & (length > 0)
    scale = np.maximum(near, 0.25 * inner)
    return seg, thr, f0, f1, length, scale, keep, top


def layout(points: NDArray, positions: NDArray, intensities: NDArray, model: DetectionModel,
           pieces: tuple | None = None, refine: int = 1) -> Layout:
    """Lay out the quadrature of a path's excess hazard.

    Parameters
    ----------
    points : ndarray
        The polyline (M, 3) [m].
    positions, intensities : ndarray
        Threats (N, 3) [m] and F (N,).
    model : DetectionModel
        The radar model.
    pieces : tuple, optional
        ``(segment, threat, f0, f1)`` of the seen pieces (terrain masking,
        :func:`threat_planner.core.cost.masking.visible_pieces`); None: every threat sees
        every segment whole.
    refine : int
        Pieces per quadrature piece (each split in `refine` equal parts).

    """
    return _layout(_pairs(points, positions, intensities, model, pieces), refine)


def _layout(pairs: tuple, refine: int) -> Layout:
    seg, thr, f0, f1, length, scale, keep, _ = pairs
    count = np.clip(np.ceil(length / (PIECE * scale)), 1, MAX_PIECES).astype(np.int64)
    count = np.where(keep, count * int(refine), 0)
    piece = np.repeat(np.arange(len(seg)), count)
    first = np.cumsum(count) - count
    j = np.arange(len(piece)) - first[piece]
    width = (f1 - f0)[piece] / count[piece]
    lo = f0[piece] + j * width
    ratio = (length / scale)[piece] / count[piece]
    far, short = ratio <= FAR, (ratio > FAR) & (ratio <= SHORT)
    parts = []
    for order, pick in ((FAR_ORDER, far), (SHORT_ORDER, short), (ORDER, ratio > SHORT)):
        nodes, weights = _rule(order)
        parts.append((np.repeat(piece[pick], order),
                      (lo[pick, None] + nodes[None, :] * width[pick, None]).reshape(-1),
                      (weights[None, :] * width[pick, None]).reshape(-1)))
    node_piece, node_t, node_w = (np.concatenate(x) for x in zip(*parts))
    return Layout(seg=seg, thr=thr, f0=f0, f1=f1, node_piece=node_piece, node_t=node_t,
                  node_w=node_w)


def _subset(pairs: tuple, pick: NDArray) -> tuple:
    return tuple(x[pick] for x in pairs)


def hazard_and_gradient(points: NDArray, positions: NDArray, intensities: NDArray,
                        model: DetectionModel, lay: Layout, want_grad: bool = True
                        ) -> tuple[NDArray, NDArray | None]:
    """Each threat's H_i on a fixed layout, and dH/dpoints (M, 3) (None unless `want_grad`).

    The floor P_fa (f1 - f0) l / (v T) of each piece is exact; the excess is the layout's
    quadrature. The gradient is exact for this layout.
    """
    points = np.asarray(points, float)
    positions = np.asarray(positions, float)
    f = np.asarray(intensities, float)
    a, b = points[:-1], points[1:]
    e_all = b - a
    l_all = np.linalg.norm(e_all, axis=1)
    unit = e_all / np.where(l_all > 0, l_all, 1.0)[:, None]
    vt = model.metres_per_scan
    n_thr = len(positions)
    span = lay.f1 - lay.f0
    per = np.bincount(lay.thr, model.p_fa * span * l_all[lay.seg], n_thr) / vt
    grad = np.zeros_like(points) if want_grad else None
    if want_grad and len(lay.seg):
        # d floor / d points, through the segment lengths.
        w_seg = np.bincount(lay.seg, span, len(a)) * model.p_fa / vt
        g_l = w_seg[:, None] * unit
        grad[:-1] -= g_l
        grad[1:] += g_l
    if len(lay.node_t) == 0:
        return per, grad
    piece = lay.node_piece
    seg, thr = lay.seg[piece], lay.thr[piece]
    t = lay.node_t
    e = e_all[seg]
    g = positions[thr] - (a[seg] + t[:, None] * e)
    s, ds_dg, ds_de = snr(model, f[thr], e, g, want_grad)
    p, dp = p_detect_scan(s, model.p_fa, model.swerling, want_grad)
    excess = p - model.p_fa
    length = l_all[seg]
    per = per + np.bincount(thr, lay.node_w * length * excess, n_thr) / vt
    if not want_grad:
        return per, None
    wl = (lay.node_w * length / vt)[:, None]
    g_g = wl * dp[:, None] * ds_dg            # d/dg of each node's term
    g_e = wl * dp[:, None] * ds_de + (lay.node_w * excess / vt)[:, None] * unit[seg]
    # g = q - (1 - t) a - t b, e = b - a.
    ga = -(1.0 - t)[:, None] * g_g - g_e
    gb = -t[:, None] * g_g + g_e
    for k in range(3):
        grad[:-1, k] += np.bincount(seg, ga[:, k], len(a))
        grad[1:, k] += np.bincount(seg, gb[:, k], len(a))
    return per, grad


def path_hazard(points: NDArray, positions: NDArray, intensities: NDArray,
                model: DetectionModel, pieces: tuple | None = None) -> DetectionReport:
    """Return the exact cumulative detection of a polyline.

    Pieces no longer than SETTLED of their scale, out of their radar's range, are summed
    once; the others' layout is
    doubled until H changes by less than TOLERANCE (10,000 threats: 1.6 s when every pair
    was doubled). Against scipy's quad on 20 threats: 1e-10 (ellipsoid, Swerling 0).
    """
    positions = np.asarray(positions, float).reshape(-1, 3)
    if len(points) < 2 or len(positions) == 0:
        return DetectionReport(0.0, 0.0, np.zeros(len(positions)))
    pairs = _pairs(points, positions, intensities, model, pieces)
    length, scale, top = pairs[4], pairs[5], pairs[7]
    # Beyond a radar's range (SNR < 1 all along) P_d is smooth on the distance's scale;
    # inside it, a steady target's P_d rises from P_fa to 1 over a few % of it.
    settled = (length <= SETTLED * scale) & (top < 1.0)
    evaluate = hazard_and_gradient
    if len(positions) >= COMPILED_THREATS:
        from threat_planner.core.detection.kernels import compiled_hazard as evaluate
    far, _ = evaluate(points, positions, intensities, model,
                      _layout(_subset(pairs, settled), 1), want_grad=False)
    near_pairs = _subset(pairs, ~settled)
    refine, previous = 1, None
    while True:
        per, _ = evaluate(points, positions, intensities, model,
                          _layout(near_pairs, refine), want_grad=False)
        per = per + far
        total = float(per.sum())
        if previous is not None and abs(total - previous) <= TOLERANCE * max(total, 1e-300):
            break
        if refine >= 64:
            break
        previous, refine = total, refine * 2
    return DetectionReport(p_detect=float(-math.expm1(-total)), hazard=total, per_threat=per)


def profile(points: NDArray, positions: NDArray, intensities: NDArray, model: DetectionModel,
            per_segment: int = 16) -> tuple[NDArray, NDArray]:
    """P_d per scan of each threat along a polyline, for figures (terrain not applied).

    Returns
    -------
    tuple
        ``(s, p_d)``: distance along the path at each sample (K,) [m] and P_d of each
        threat there (N, K).

    """
    points = np.asarray(points, float)
    positions = np.asarray(positions, float).reshape(-1, 3)
    a, e = points[:-1], np.diff(points, axis=0)
    t = (np.arange(per_segment) + 0.5) / per_segment
    seg = np.repeat(np.arange(len(a)), per_segment)
    frac = np.tile(t, len(a))
    p = a[seg] + frac[:, None] * e[seg]
    lengths = np.linalg.norm(e, axis=1)
    s = (np.concatenate([[0.0], np.cumsum(lengths)])[:-1])[seg] + frac * lengths[seg]
    n, k = len(positions), len(p)
    ee = np.repeat(e[seg][None], n, 0).reshape(-1, 3)
    g = (positions[:, None, :] - p[None, :, :]).reshape(-1, 3)
    f = np.repeat(np.asarray(intensities, float), k)
    values, _ = p_detect_scan(snr(model, f, ee, g)[0], model.p_fa, model.swerling)
    return s, values.reshape(n, k)
