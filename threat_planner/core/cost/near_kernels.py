"""Compiled (numba) cut-off segment costs: the near threats found on a uniform grid.

:meth:`~threat_planner.core.world.threats.ThreatField.near_pairs` answers "which threats lie
within ``radius + L/2`` of each segment's midpoint" with one k-d tree ball query per
segment and hands the pairs to the cost kernel; on the 10,000-threat network (133,000
edges, 2.9 million pairs) the queries alone took 0.94 s and the costs 0.42 s (measured in
``bench/results/profile_scale_*.txt``). Here the threats are binned once into cubic cells
of the cut-off's size, and each segment visits the cells its ball overlaps, applies the
same test and adds each near threat's closed-form integral on the spot: the same pairs,
the same sums (up to their order), no pair list; the segments run in parallel.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.kernels import (_FROZEN_C2, _FROZEN_C3, _frozen, njit, PARALLEL_LOCK,
                                              prange)
from threat_planner.core.cost.pair_integrals import _pair_integral

__all__ = ['near_segment_costs']

#: Most grid cells per threat: a cut-off far below the spacing would make empty cells.
_CELLS_PER_THREAT = 8


@njit(cache=True)
def _bin(positions, origin, cell, dims):
    """Sort the threats by cell: (start of each cell's run, threat order), counting."""
    n = positions.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    ids = np.empty(n, np.int64)
    start = np.zeros(ncell + 1, np.int64)
    for i in range(n):
        ix = min(max(int((positions[i, 0] - origin[0]) / cell), 0), dims[0] - 1)
        iy = min(max(int((positions[i, 1] - origin[1]) / cell), 0), dims[1] - 1)
        iz = min(max(int((positions[i, 2] - origin[2]) / cell), 0), dims[2] - 1)
        ids[i] = (ix * dims[1] + iy) * dims[2] + iz
        start[ids[i] + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[ids[i]]] = i
        fill[ids[i]] += 1
    return start, order


@njit(cache=True, inline='always')
def _cells(m, reach, origin, cell, dim):
    """First and last cell index along one axis of the interval m +- reach."""
    first = min(max(int(math.floor((m - reach - origin) / cell)), 0), dim - 1)
    last = min(max(int(math.floor((m + reach - origin) / cell)), 0), dim - 1)
    return first, last


@njit(cache=True, parallel=True)
def _near_costs(a, b, positions, f, radius, origin, cell, dims, start, order, c2, c3,
                out, near_f):
    """Cut-off J_R and the near intensity of every segment into out and near_f."""
    for s in prange(a.shape[0]):
        dx = b[s, 0] - a[s, 0]
        dy = b[s, 1] - a[s, 1]
        dz = b[s, 2] - a[s, 2]
        ln = math.sqrt(dx * dx + dy * dy + dz * dz)
        mx, my, mz = a[s, 0] + 0.5 * dx, a[s, 1] + 0.5 * dy, a[s, 2] + 0.5 * dz
        reach = radius + 0.5 * ln
        reach2 = reach * reach
        x0, x1 = _cells(mx, reach, origin[0], cell, dims[0])
        y0, y1 = _cells(my, reach, origin[1], cell, dims[1])
        z0, z1 = _cells(mz, reach, origin[2], cell, dims[2])
        total = 0.0
        fsum = 0.0
        for ix in range(x0, x1 + 1):
            for iy in range(y0, y1 + 1):
                base = (ix * dims[1] + iy) * dims[2]
                for c in range(base + z0, base + z1 + 1):
                    for q in range(start[c], start[c + 1]):
                        i = order[q]
                        qx = positions[i, 0] - mx
                        qy = positions[i, 1] - my
                        qz = positions[i, 2] - mz
                        if qx * qx + qy * qy + qz * qz > reach2:
                            continue
                        fsum += f[i]
                        total += f[i] * _pair_integral(a, b, s, positions, i, c2, c3)
        out[s] = total
        near_f[s] = fsum


def near_segment_costs(a: NDArray, b: NDArray, positions: NDArray, intensities: NDArray,
                       radius: float) -> tuple[NDArray, NDArray]:
    """Cut-off J_R of each segment and the most the dropped threats can add to it.

    The threats counted are those of ``ThreatField.near_pairs``: within ``radius + L/2``
    of the segment's midpoint, which holds every threat within ``radius`` of the segment.

    Parameters
    ----------
    a, b : ndarray
        Segment starts and ends, (S, 3) [m].
    positions : ndarray
        Threat positions, (N, 3) [m].
    intensities : ndarray
        Threat intensities F, (N,).
    radius : float
        Cut-off distance [m], > 0.

    Returns
    -------
    tuple
        ``(costs (S,), bound (S,))``, bound = (sum of the dropped F) L / radius^4.

    """
    a = np.ascontiguousarray(a, float)
    b = np.ascontiguousarray(b, float)
    out = np.zeros(len(a))
    near_f = np.zeros(len(a))
    if len(a) == 0 or len(positions) == 0:
        return out, near_f
    positions = _frozen(positions)
    origin = positions.min(axis=0)
    extent = np.maximum(positions.max(axis=0) - origin, 1e-12)
    # Cells of the cut-off's size, coarsened when that would be many per threat.
    cell = max(float(radius),
               float(np.prod(extent) / (_CELLS_PER_THREAT * len(positions))) ** (1 / 3))
    dims = np.minimum(np.floor(extent / cell).astype(np.int64) + 1, 1 << 20)
    start, order = _bin(positions, origin, cell, dims)
    with PARALLEL_LOCK:
        _near_costs(a, b, positions, _frozen(intensities), float(radius), origin, cell,
                    dims, start, order, _FROZEN_C2, _FROZEN_C3, out, near_f)
    length = np.linalg.norm(b - a, axis=1)
    total = float(np.sum(intensities))
    return out, np.maximum(total - near_f, 0.0) * length / radius ** 4
