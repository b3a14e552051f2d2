"""The far threats of a cut-off minimisation, aggregated into cells (a Barnes-Hut tree).

Under a cut-off the optimiser counted only the threats within it of each segment, and the
rest of J_R was lost to it: on fresh 1,000-threat fields of ground radars at w 0.8 (every
radar beyond the cut-off of a path flown above them) it traded the far threats' J for
length and ended 17 % above its own start. Here every threat counts: the near ones
exactly, as before, and the far ones through cells of a grid hierarchy, each a pseudo-threat
of its members' total F at their F-weighted centroid (its monopole), taken where the cell
is at least its own size and the cut-off from the segment. Each threat is counted once per
segment, exactly or in one cell. Only the optimiser's objective uses the cells: every J
reported is exact.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ['FarField']

#: Leaf cells' edge, in cut-offs (the cells whose members are counted one by one).
LEAF_CUTOFFS = 0.25
#: A cell counts as one pseudo-threat from a segment at least this many of its own
#: extents away (and never nearer than the cut-off).
OPENING = 1.0
#: Top of the hierarchy: stop merging cells once this few remain.
TOP_CELLS = 8


class FarField:
    """Cells of a threat field for the pairs of a cut-off radius.

    Parameters
    ----------
    positions : ndarray, shape (n, 3)
        Threat positions [m].
    intensities : ndarray, shape (n,)
        Threat intensities F.
    radius : float
        Cut-off [m]: every threat within it of a segment is counted exactly.

    Attributes
    ----------
    positions, intensities : ndarray
        The threats followed by every cell's pseudo-threat, level by level: the arrays
        the pairs of :meth:`pairs` index.
    """

    def __init__(self, positions: NDArray, intensities: NDArray, radius: float) -> None:
        pos = np.asarray(positions, float)
        f = np.asarray(intensities, float)
        self.radius = float(radius)
        n = len(pos)
        origin = pos.min(axis=0) if n else np.zeros(3)
        keys = np.floor((pos - origin) / (LEAF_CUTOFFS * self.radius)).astype(np.int64)
        cells, cell_of = np.unique(keys, axis=0, return_inverse=True)
        cell_of = cell_of.reshape(-1)
        cell_of_leaf = cell_of
        # Levels bottom up: (members' box lo, hi, its largest edge, parent, first index).
        self._levels: list[tuple] = []
        extra_pos, extra_f, offset = [], [], n
        while True:
            m = len(cells)
            lo = np.full((m, 3), np.inf)
            hi = np.full((m, 3), -np.inf)
            np.minimum.at(lo, cell_of, pos)
            np.maximum.at(hi, cell_of, pos)
            total = np.bincount(cell_of, f, m)
            extra_pos.append(np.stack([np.bincount(cell_of, f * pos[:, k], m)
                                       for k in range(3)], axis=1) / total[:, None])
            extra_f.append(total)
            if m <= TOP_CELLS:
                self._levels.append((lo, hi, (hi - lo).max(axis=1), None, offset))
                break
            # The keys halve exactly, so each cell lies in one parent.
            cells, parent = np.unique(cells // 2, axis=0, return_inverse=True)
            parent = parent.reshape(-1)
            self._levels.append((lo, hi, (hi - lo).max(axis=1), parent, offset))
            cell_of = parent[cell_of]
            offset += m
        self.positions = np.ascontiguousarray(np.vstack([pos] + extra_pos))
        self.intensities = np.ascontiguousarray(np.concatenate([f] + extra_f))
        # Children of each cell (CSR, by level), and the members of each leaf.
        self._children = {d: _csr(self._levels[d - 1][3], len(self._levels[d][0]))
                          for d in range(1, len(self._levels))}
        self._members, self._member_start = _csr(cell_of_leaf, len(self._levels[0][0]))

    def pairs(self, a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
        """(segment, index) pairs covering every threat once per segment, by segment.

        Parameters
        ----------
        a, b : ndarray, shape (S, 3)
            Segment starts and ends [m].

        Returns
        -------
        (ndarray, ndarray)
            Segment indices (ascending) and indices into :attr:`positions`: threats
            near the segment and cells far from it.
        """
        a, b = np.asarray(a, float), np.asarray(b, float)
        mid = 0.5 * (a + b)
        half = 0.5 * np.sqrt(((b - a) ** 2).sum(axis=1))
        seg_parts, idx_parts = [], []
        # Top down, only below cells that were neither far nor under a far one: a cell
        # counts where it is far and no ancestor counted already.
        top = len(self._levels) - 1
        cells = len(self._levels[top][0])
        s = np.repeat(np.arange(len(a)), cells)
        c = np.tile(np.arange(cells), len(a))
        for depth in range(top, -1, -1):
            lo, hi, extent, _, start = self._levels[depth]
            m = mid[s]
            gap = m - np.clip(m, lo[c], hi[c])
            dist = np.sqrt((gap ** 2).sum(axis=1)) - half[s]
            far = (dist >= self.radius) & (dist >= OPENING * extent[c])
            seg_parts.append(s[far])
            idx_parts.append(start + c[far])
            s, c = s[~far], c[~far]
            if depth:
                s, c = _expand(s, c, *self._children[depth])
            # (s, c) in the order of a segments x cells table read row by row.
            order = np.lexsort((c, s))
            s, c = s[order], c[order]
        # Leaves neither counted nor under a counted cell: their members one by one.
        s, c = _expand(s, c, self._members, self._member_start)
        seg_parts.append(s)
        idx_parts.append(c)
        seg = np.concatenate(seg_parts).astype(np.int64)
        idx = np.concatenate(idx_parts).astype(np.int64)
        order = np.argsort(seg, kind='stable')
        return seg[order], idx[order]


def _expand(s: NDArray, c: NDArray, items: NDArray, first: NDArray) -> tuple[NDArray, NDArray]:
    """Each (s, c) as (s, item) for every item of c (CSR: items[first[c]:first[c + 1]])."""
    counts = first[c + 1] - first[c]
    at = np.repeat(first[c] - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
    return np.repeat(s, counts), items[at]


def _csr(parent: NDArray, count: int) -> tuple[NDArray, NDArray]:
    """Return (items by parent, first item of each parent) for ``count`` parents."""
    items = np.argsort(parent, kind='stable')
    return items, np.searchsorted(parent[items], np.arange(count + 1))
