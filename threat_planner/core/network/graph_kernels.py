"""Compiled (numba) network kernels: Dijkstra over a fixed graph, and the cells' incentres.

``best`` runs a dozen Dijkstras a plan on graphs of a few hundred nodes (the penalised
alternative routes over the network, the routes over the box's surface lattice), each with
new weights on the same edges. scipy's ``csgraph.dijkstra`` needs a new sparse matrix every
time; here the graph's structure is built once and only its weights change (12 bundled
cases, one run before and one after, not side by side: the alternative routes 2.7 -> 0.5 ms
a plan, the surface routes 4.2 -> 1.6 ms with their lattice cached too). The incentres
of the cells (:func:`.partition.incentres`) take 16 us on 175 cells and 2.2 ms on 65,000
against numpy's 0.26 and 47 ms.
"""

from __future__ import annotations

import heapq

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.kernels import njit

__all__ = ['Graph']

#: csgraph's convention, kept: a zero weight would mean no edge there, so the least
#: weight an edge gets is this.
MIN_WEIGHT = 1e-12


@njit(cache=True)
def _dijkstra(indptr, indices, data, source, target, dist, pred):
    """Least total weight from source into dist, predecessors into pred.

    The search stops once it takes target (target < 0: never): dist[target] and target's
    chain of predecessors are then final, the other entries upper bounds.
    """
    dist[:] = np.inf
    pred[:] = -1
    done = np.zeros(dist.shape[0], np.bool_)
    dist[source] = 0.0
    heap = [(0.0, source)]
    while heap:
        d, u = heapq.heappop(heap)
        if done[u]:
            continue
        done[u] = True
        if u == target:
            break
        for k in range(indptr[u], indptr[u + 1]):
            v = indices[k]
            nd = d + data[k]
            if nd < dist[v]:
                dist[v] = nd
                pred[v] = u
                heapq.heappush(heap, (nd, v))


class Graph:
    """An undirected graph of ``n`` nodes and fixed edges whose weights are set per search.

    Parameters
    ----------
    n : int
        Nodes.
    edges : ndarray
        (E, 2) node pairs.

    """

    def __init__(self, n: int, edges: NDArray) -> None:
        edges = np.asarray(edges, np.int64).reshape(-1, 2)
        rows = np.concatenate([edges[:, 0], edges[:, 1]])
        cols = np.concatenate([edges[:, 1], edges[:, 0]])
        order = np.argsort(rows, kind='stable')
        self.n = int(n)
        self.indices = np.ascontiguousarray(cols[order])
        self.indptr = np.zeros(self.n + 1, np.int64)
        np.cumsum(np.bincount(rows, minlength=self.n), out=self.indptr[1:])
        # Entry k of the CSR arrays holds edge slot[k]'s weight (each edge twice).
        self.slot = np.ascontiguousarray(np.concatenate([np.arange(len(edges))] * 2)[order])
        self.data = np.zeros(len(rows))

    def shortest(self, weights: NDArray, source: int,
                 target: int = -1) -> tuple[NDArray, NDArray]:
        """Least total weights from ``source`` and the predecessors (-1: none), (n,) each.

        With a ``target`` the search stops there: only ``dist[target]`` and the chain of
        predecessors from it are then final.
        """
        self.data[:] = np.maximum(np.asarray(weights, float), MIN_WEIGHT)[self.slot]
        dist = np.empty(self.n)
        pred = np.empty(self.n, np.int64)
        _dijkstra(self.indptr, self.indices, self.data, int(source), int(target), dist, pred)
        return dist, pred


def warm_up() -> None:
    """Compile (or load from the cache) the search once, on a tiny graph."""
    Graph(3, np.array([[0, 1], [1, 2]])).shortest(np.array([1.0, 2.0]), 0)


@njit(cache=True, inline='always')
def _face_area(c, m, i, j, k):
    """Area of the triangle of corners i, j, k of cell m."""
    ux = c[m, j, 0] - c[m, i, 0]
    uy = c[m, j, 1] - c[m, i, 1]
    uz = c[m, j, 2] - c[m, i, 2]
    vx = c[m, k, 0] - c[m, i, 0]
    vy = c[m, k, 1] - c[m, i, 1]
    vz = c[m, k, 2] - c[m, i, 2]
    x = uy * vz - uz * vy
    y = uz * vx - ux * vz
    z = ux * vy - uy * vx
    return 0.5 * np.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def incentre_kernel(corners, centres, radii):
    """Incentre and inradius of each tetrahedron (M, 4, 3) into centres and radii."""
    areas = np.empty(4)
    for m in range(corners.shape[0]):
        # Face i is the one opposite corner i.
        areas[0] = _face_area(corners, m, 1, 2, 3)
        areas[1] = _face_area(corners, m, 0, 2, 3)
        areas[2] = _face_area(corners, m, 0, 1, 3)
        areas[3] = _face_area(corners, m, 0, 1, 2)
        total = areas[0] + areas[1] + areas[2] + areas[3]
        safe = total if total > 0 else 1.0
        for k in range(3):
            if total > 0:
                acc = 0.0
                for i in range(4):
                    acc += areas[i] * corners[m, i, k]
                centres[m, k] = acc / safe
            else:
                centres[m, k] = (corners[m, 0, k] + corners[m, 1, k] + corners[m, 2, k]
                                 + corners[m, 3, k]) / 4.0
        ax = corners[m, 1, 0] - corners[m, 0, 0]
        ay = corners[m, 1, 1] - corners[m, 0, 1]
        az = corners[m, 1, 2] - corners[m, 0, 2]
        ux = corners[m, 2, 0] - corners[m, 0, 0]
        uy = corners[m, 2, 1] - corners[m, 0, 1]
        uz = corners[m, 2, 2] - corners[m, 0, 2]
        vx = corners[m, 3, 0] - corners[m, 0, 0]
        vy = corners[m, 3, 1] - corners[m, 0, 1]
        vz = corners[m, 3, 2] - corners[m, 0, 2]
        volume = abs(ax * (uy * vz - uz * vy) + ay * (uz * vx - ux * vz)
                     + az * (ux * vy - uy * vx)) / 6.0
        radii[m] = 3.0 * volume / safe
