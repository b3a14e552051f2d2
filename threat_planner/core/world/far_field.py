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

    The pairs themselves are :func:`threat_planner.core.cost.far_kernels.far_pairs`'s.

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
        the pairs index.
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
        levels: list[tuple] = []
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
                levels.append((lo, hi, (hi - lo).max(axis=1), None, offset))
                break
            # The keys halve exactly, so each cell lies in one parent.
            cells, parent = np.unique(cells // 2, axis=0, return_inverse=True)
            parent = parent.reshape(-1)
            levels.append((lo, hi, (hi - lo).max(axis=1), parent, offset))
            cell_of = parent[cell_of]
            offset += m
        self.positions = np.ascontiguousarray(np.vstack([pos] + extra_pos))
        self.intensities = np.ascontiguousarray(np.concatenate([f] + extra_f))
        # Every level's cells in one table, for the compiled walk (cost.far_kernels): cell
        # g (bottom up, level by level) is pseudo-threat n + g of positions, and
        # items[first[g]:first[g + 1]] are its children's cell numbers, or a leaf's threats.
        firsts, items, base = [], [], 0
        for depth in range(len(levels)):
            if depth == 0:
                kids, start = _csr(cell_of_leaf, len(levels[0][0]))
            else:
                kids, start = _csr(levels[depth - 1][3], len(levels[depth][0]))
                kids = kids + (levels[depth - 1][4] - n)
            firsts.append(start[:-1] + base)
            items.append(kids)
            base += len(kids)
        self.n_threats = n
        self.n_leaf = len(levels[0][0])
        self.top = levels[-1][4] - n
        self.opening = OPENING
        self.first = np.ascontiguousarray(np.concatenate(firsts + [[base]]), np.int64)
        self.items = np.ascontiguousarray(np.concatenate(items), np.int64)
        self.cell_lo = np.ascontiguousarray(np.vstack([lv[0] for lv in levels]))
        self.cell_hi = np.ascontiguousarray(np.vstack([lv[1] for lv in levels]))
        self.cell_extent = np.ascontiguousarray(np.concatenate([lv[2] for lv in levels]))


def _csr(parent: NDArray, count: int) -> tuple[NDArray, NDArray]:
    """Return (items by parent, first item of each parent) for ``count`` parents."""
    items = np.argsort(parent, kind='stable')
    return items, np.searchsorted(parent[items], np.arange(count + 1))
