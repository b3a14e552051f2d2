"""Terrain masking: a radar counts only along the parts of a segment it sees.

Each (segment, radar) pair is sampled at fractions f_0 = 0 < ... < f_m = 1 of the segment;
line of sight from the radar to each sample is decided exactly (``Terrain.visible``). Where
two neighbouring samples disagree, the shadow edge between them is located by bisection to
``EDGE_TOLERANCE`` of the segment's length. On every visible piece the closed-form integral
of F/d^4 holds, so J_R is exact up to the edge location and to shadows (or sunlit gaps)
narrower than the sample spacing, which may be missed: the spacing is at most
``SAMPLE_STEPS_PER_CELL`` samples per terrain cell (half a grid spacing by default).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.closed_form import _geometry, _pair_gradient, Cost, pair_integrals
from threat_planner.core.world.terrain import Terrain

__all__ = ['visible_fractions', 'masked_segment_costs', 'masked_cost_and_gradient',
           'visible_pieces', 'masked_path_j_r',
           'EDGE_TOLERANCE', 'SAMPLE_STEPS_PER_CELL']

#: Shadow edges located to this fraction of the segment's length.
EDGE_TOLERANCE = 1e-6
#: Samples per terrain grid spacing along a segment.
SAMPLE_STEPS_PER_CELL = 2.0


def visible_fractions(terrain: Terrain, a: NDArray, b: NDArray, radar: NDArray,
                      samples: int, tolerance: float = EDGE_TOLERANCE) -> NDArray:
    """Visible part of each of the m = samples - 1 pieces of each pair's segment.

    Args:
        terrain: The terrain.
        a: Segment starts (P, 3) [m].
        b: Segment ends (P, 3) [m].
        radar: Radar position of each pair (P, 3) [m].
        samples: Samples per segment (>= 2), ends included.
        tolerance: Edge location, as a fraction of the segment.

    Returns:
        ``(P, m, 2)`` fractions ``[lo, hi]`` of the visible part of each piece; lo = hi
        where the piece is hidden.
    """
    p = len(a)
    f = np.linspace(0.0, 1.0, samples)
    d = b - a
    pts = a[:, None, :] + f[None, :, None] * d[:, None, :]
    rad = np.repeat(radar[:, None, :], samples, axis=1)
    vis = terrain.visible(rad.reshape(-1, 3), pts.reshape(-1, 3)).reshape(p, samples)
    lo = np.broadcast_to(f[:-1], (p, samples - 1)).copy()
    hi = np.broadcast_to(f[1:], (p, samples - 1)).copy()
    out = np.stack([lo, hi], axis=-1)
    v0, v1 = vis[:, :-1], vis[:, 1:]
    out[~v0 & ~v1] = out[~v0 & ~v1][:, :1]      # hidden: empty [lo, lo]
    edge = v0 != v1
    if np.any(edge):
        ip, ik = np.nonzero(edge)
        left, right = lo[ip, ik], hi[ip, ik]
        seen_left = v0[ip, ik]
        steps = int(np.ceil(np.log2(max((right - left).max(), 1e-300) / tolerance)))
        for _ in range(max(steps, 1)):
            mid = 0.5 * (left + right)
            q = a[ip] + mid[:, None] * d[ip]
            same = terrain.visible(radar[ip], q) == seen_left
            left, right = np.where(same, mid, left), np.where(same, right, mid)
        cut = 0.5 * (left + right)
        out[ip, ik, 0] = np.where(seen_left, lo[ip, ik], cut)
        out[ip, ik, 1] = np.where(seen_left, cut, hi[ip, ik])
    return out


def _samples(terrain: Terrain, lengths: NDArray) -> int:
    step = terrain.resolution / SAMPLE_STEPS_PER_CELL
    return int(np.clip(np.ceil(lengths.max(initial=0.0) / step), 1, 4096)) + 1


def masked_segment_costs(a: NDArray, b: NDArray, positions: NDArray, intensities: NDArray,
                         terrain: Terrain, samples: int | None = None,
                         chunk: int = 4096) -> NDArray:
    """Masked threat cost of each segment: sum_i F_i * integral over the seen parts.

    Args:
        a: Segment starts (S, 3) [m].
        b: Segment ends (S, 3) [m].
        positions: Radar positions (N, 3) [m].
        intensities: F of each radar (N,).
        terrain: The terrain that masks.
        samples: Samples per segment; None for SAMPLE_STEPS_PER_CELL per grid spacing of
            the longest segment in each chunk.
        chunk: Pairs per batch.

    Returns:
        Array (S,) of threat costs.
    """
    a, b = np.atleast_2d(np.asarray(a, float)), np.atleast_2d(np.asarray(b, float))
    positions = np.asarray(positions, float).reshape(-1, 3)
    f = np.asarray(intensities, float)
    s_n, n = len(a), len(positions)
    out = np.zeros(s_n)
    if n == 0 or s_n == 0:
        return out
    seg = np.repeat(np.arange(s_n), n)
    thr = np.tile(np.arange(n), s_n)
    lengths = np.linalg.norm(b - a, axis=1)
    order = np.argsort(lengths[seg], kind='stable')
    for lo in range(0, len(order), chunk):
        idx = order[lo:lo + chunk]
        s, t = seg[idx], thr[idx]
        m = samples or _samples(terrain, lengths[s])
        fr = visible_fractions(terrain, a[s], b[s], positions[t], m)
        d = (b[s] - a[s])[:, None, :]
        pa = a[s][:, None, :] + fr[..., 0:1] * d
        pb = a[s][:, None, :] + fr[..., 1:2] * d
        rep = positions[t][:, None, :].repeat(m - 1, axis=1)
        vals = pair_integrals(pa.reshape(-1, 3), pb.reshape(-1, 3), rep.reshape(-1, 3))
        out += np.bincount(s, vals.reshape(len(s), -1).sum(axis=1) * f[t], s_n)
    return out


def masked_path_j_r(points: NDArray, positions: NDArray, intensities: NDArray,
                    terrain: Terrain) -> float:
    """Masked J_R of a polyline (n, 3)."""
    points = np.asarray(points, float)
    return float(masked_segment_costs(points[:-1], points[1:], positions, intensities,
                                      terrain).sum())


def visible_pieces(points: NDArray, positions: NDArray, terrain: Terrain, samples: int = 9
                   ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Find the seen pieces of a polyline's segments for every radar.

    Returns:
        ``(segment, radar, f0, f1)``: each seen piece runs from fraction f0 to f1 of its
        segment.
    """
    points = np.asarray(points, float)
    a, b = points[:-1], points[1:]
    s_n, n = len(a), len(positions)
    seg = np.repeat(np.arange(s_n), n)
    thr = np.tile(np.arange(n), s_n)
    fr = visible_fractions(terrain, a[seg], b[seg], positions[thr], samples, 1e-4)
    f0, f1 = fr[..., 0].reshape(-1), fr[..., 1].reshape(-1)
    sp, tp = np.repeat(seg, samples - 1), np.repeat(thr, samples - 1)
    keep = f1 > f0
    return sp[keep], tp[keep], f0[keep], f1[keep]


def masked_cost_and_gradient(points: NDArray, positions: NDArray, intensities: NDArray,
                             w: float, pieces: tuple[NDArray, NDArray, NDArray, NDArray]
                             ) -> tuple[float, NDArray]:
    """J of a polyline with J_R over given seen pieces, and its exact gradient.

    The pieces (see visible_pieces) are held at fixed fractions of their segments, so this
    is the masked J of the path where they were found and a smooth model of it nearby;
    the optimiser re-finds them after each round.
    """
    points = np.asarray(points, float)
    a, b = points[:-1], points[1:]
    s_n = len(a)
    d = b - a
    seg_len = np.linalg.norm(d, axis=1)
    j_l = float(seg_len.sum())
    unit = d / np.where(seg_len > 0, seg_len, 1.0)[:, None]
    grad = np.zeros_like(points)
    grad[:-1] -= (1.0 - w) * unit
    grad[1:] += (1.0 - w) * unit
    sp, tp, f0, f1 = pieces
    if len(sp) == 0:
        return (1.0 - w) * j_l, grad
    pa = a[sp] + f0[:, None] * d[sp]
    pb = a[sp] + f1[:, None] * d[sp]
    cost, da, db = _pair_gradient(_geometry(pa, pb, positions[tp]),
                                  np.asarray(intensities, float)[tp])
    j_r = float(cost.sum())
    if not np.isfinite(j_r):
        return j_r, grad
    ga = (1 - f0)[:, None] * da + (1 - f1)[:, None] * db
    gb = f0[:, None] * da + f1[:, None] * db
    for k in range(3):
        grad[:-1, k] += w * np.bincount(sp, ga[:, k], s_n)
        grad[1:, k] += w * np.bincount(sp, gb[:, k], s_n)
    return w * j_r + (1.0 - w) * j_l, grad


def masked_cost(points: NDArray, threats, w: float, airspace) -> Cost:
    """Exact masked J of a polyline: J_R over the radar-visible parts only."""
    points = np.asarray(points, float)
    j_l = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    j_r = masked_path_j_r(points, threats.positions, threats.intensities, airspace.terrain)
    return Cost(w * j_r + (1.0 - w) * j_l, j_l, j_r)
