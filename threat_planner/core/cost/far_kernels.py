"""Compiled (numba) pairs of a far field: near threats one by one, far ones in cells.

:class:`~threat_planner.core.world.far_field.FarField` holds the cells; here each segment
walks them top down, level by level, and keeps a cell where it is far (at least the
cut-off and its own extent from the segment) and no ancestor was, and the members of the
leaves that never were. The numpy walk this replaced built a (segment, cell) table per
level and sorted it: 3.0 ms a pick of a 40-segment path on 10,000 threats, against
1.2 ms here (1.7 and 0.55 ms on 1,000). The pairs are the same, in the same order
(by segment; then each level's far cells top down in ascending order; then the leaves'
members), so the objective sums them in the same order as before.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.kernels import njit

__all__ = ['far_pairs']


@njit(cache=True)
def _walk(a, b, s, lo, hi, extent, first, items, n_threats, n_leaf, top, radius, opening,
          cur, nxt, leaves, out, k):
    """Segment s's pair indices into out from k (counted only if out is empty); new k."""
    write = out.shape[0] > 0
    mx = 0.5 * (a[s, 0] + b[s, 0])
    my = 0.5 * (a[s, 1] + b[s, 1])
    mz = 0.5 * (a[s, 2] + b[s, 2])
    dx = b[s, 0] - a[s, 0]
    dy = b[s, 1] - a[s, 1]
    dz = b[s, 2] - a[s, 2]
    half = 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz)
    ncur = 0
    for g in range(top, lo.shape[0]):
        cur[ncur] = g
        ncur += 1
    nleaf = 0
    while ncur > 0:
        nn = 0
        for i in range(ncur):
            g = cur[i]
            gx = mx - min(max(mx, lo[g, 0]), hi[g, 0])
            gy = my - min(max(my, lo[g, 1]), hi[g, 1])
            gz = mz - min(max(mz, lo[g, 2]), hi[g, 2])
            dist = math.sqrt(gx * gx + gy * gy + gz * gz) - half
            if dist >= radius and dist >= opening * extent[g]:
                if write:
                    out[k] = n_threats + g
                k += 1
            elif g >= n_leaf:
                for q in range(first[g], first[g + 1]):
                    nxt[nn] = items[q]
                    nn += 1
            else:
                leaves[nleaf] = g
                nleaf += 1
        nxt[:nn].sort()
        cur, nxt = nxt, cur
        ncur = nn
    for i in range(nleaf):
        g = leaves[i]
        for q in range(first[g], first[g + 1]):
            if write:
                out[k] = items[q]
            k += 1
    return k


@njit(cache=True)
def _far_pairs(a, b, lo, hi, extent, first, items, n_threats, n_leaf, top, radius, opening):
    """(segment, index) pairs of every segment, by segment: count, then fill."""
    cells = lo.shape[0]
    cur = np.empty(cells, np.int64)
    nxt = np.empty(cells, np.int64)
    leaves = np.empty(max(n_leaf, 1), np.int64)
    none = np.empty(0, np.int64)
    counts = np.empty(a.shape[0], np.int64)
    total = 0
    for s in range(a.shape[0]):
        counts[s] = _walk(a, b, s, lo, hi, extent, first, items, n_threats, n_leaf, top,
                          radius, opening, cur, nxt, leaves, none, 0)
        total += counts[s]
    seg = np.empty(total, np.int64)
    idx = np.empty(total, np.int64)
    k = 0
    for s in range(a.shape[0]):
        seg[k:k + counts[s]] = s
        k = _walk(a, b, s, lo, hi, extent, first, items, n_threats, n_leaf, top, radius,
                  opening, cur, nxt, leaves, idx, k)
    return seg, idx


def far_pairs(far, a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
    """(segment, index) pairs covering every threat once per segment, by segment.

    Parameters
    ----------
    far : FarField
        The threats' cells (:meth:`ThreatField.far_field`).
    a, b : ndarray, shape (S, 3)
        Segment starts and ends [m].

    Returns
    -------
    (ndarray, ndarray)
        Segment indices (ascending) and indices into ``far.positions``: threats near the
        segment and cells far from it.
    """
    return _far_pairs(np.ascontiguousarray(a, float), np.ascontiguousarray(b, float),
                      far.cell_lo, far.cell_hi, far.cell_extent, far.first, far.items,
                      far.n_threats, far.n_leaf, far.top, far.radius, far.opening)
