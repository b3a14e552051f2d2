"""The grid floor: a 26-connected grid over the box, exact J of every edge, Dijkstra.

:func:`build_grid` costs every edge with the library's closed form
(:func:`threat_planner.core.cost.closed_form.segment_threat_costs`); :func:`grid_floor` is
the least-J path on it, :func:`least_route` the search the yardstick's routes share.
"""

from __future__ import annotations

from dataclasses import dataclass
import time
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from threat_planner.core.cost.closed_form import path_cost, segment_threat_costs
from threat_planner.core.world.threats import Box, ThreatField


@dataclass
class GridGraph:
    """A 26-connected grid over the box with the start and goal joined in.

    Attributes
    ----------
    nodes : ndarray, shape (M, 3)
        Grid nodes, then the start (index M-2) and the goal (index M-1) [m].
    edge_a, edge_b : ndarray, shape (E,)
        Edge end indices.
    length : ndarray, shape (E,)
        Edge lengths [m].
    threat : ndarray, shape (E,)
        Edge threat costs J_R (exact, closed form).
    build_s : float
        Seconds spent building the graph and its edge costs.
    """

    nodes: NDArray
    edge_a: NDArray
    edge_b: NDArray
    length: NDArray
    threat: NDArray
    build_s: float

    @property
    def start(self) -> int:
        """Index of the start node."""
        return len(self.nodes) - 2

    @property
    def goal(self) -> int:
        """Index of the goal node."""
        return len(self.nodes) - 1


def _grid_edges(n: int) -> tuple[NDArray, NDArray]:
    """Both end indices of every 26-neighbour edge of an n x n x n grid (each once)."""
    idx = np.arange(n ** 3).reshape(n, n, n)
    src, dst = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if (dx, dy, dz) <= (0, 0, 0):
                    continue
                sl_a, sl_b = [], []
                for dd in (dx, dy, dz):
                    sl_a.append(slice(max(0, -dd), n - max(0, dd)))
                    sl_b.append(slice(max(0, dd), n - max(0, -dd)))
                src.append(idx[tuple(sl_a)].ravel())
                dst.append(idx[tuple(sl_b)].ravel())
    return np.concatenate(src), np.concatenate(dst)


def _cell_neighbours(point: NDArray, lo: NDArray, step: NDArray, n: int) -> NDArray:
    """Grid node indices within one step (per axis) of the node nearest the point."""
    i0 = np.clip(np.rint((point - lo) / step).astype(int), 0, n - 1)
    rng = [np.arange(max(0, i - 1), min(n, i + 2)) for i in i0]
    ii, jj, kk = np.meshgrid(*rng, indexing='ij')
    return ((ii * n + jj) * n + kk).ravel()


def build_grid(threats: ThreatField, start: NDArray, goal: NDArray, box: Box,
               n: int = 21) -> GridGraph:
    """Build the grid floor's graph and every edge's exact J_R.

    Parameters
    ----------
    threats : ThreatField
        The threats.
    start, goal : ndarray, shape (3,)
        End points [m]; each is joined to the (up to 27) grid nodes around it.
    box : Box
        Flight box, gridded with n nodes per axis.
    n : int
        Nodes per axis.

    Returns
    -------
    GridGraph
        The graph; J_R of all edges from one vectorised closed-form call.
    """
    t0 = time.perf_counter()
    axes = [np.linspace(box.lo[i], box.hi[i], n) for i in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing='ij')
    grid = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    step = (box.hi - box.lo) / (n - 1)
    a, b = _grid_edges(n)
    s_idx, g_idx = n ** 3, n ** 3 + 1
    near_s = _cell_neighbours(np.asarray(start, float), box.lo, step, n)
    near_g = _cell_neighbours(np.asarray(goal, float), box.lo, step, n)
    a = np.concatenate([a, np.full(len(near_s), s_idx), near_g])
    b = np.concatenate([b, near_s, np.full(len(near_g), g_idx)])
    nodes = np.vstack([grid, start, goal])
    length = np.linalg.norm(nodes[b] - nodes[a], axis=1)
    threat = segment_threat_costs(nodes[a], nodes[b], threats.positions, threats.intensities)
    return GridGraph(nodes, a, b, length, threat, time.perf_counter() - t0)


def edge_weights(graph: GridGraph, w: float) -> tuple[NDArray, NDArray]:
    """Return J of every edge (zeros raised to 1e-300) and the mask of the finite ones."""
    weight = w * graph.threat + (1.0 - w) * graph.length
    ok = np.isfinite(weight)
    # csgraph drops explicit zeros; only a start or goal sitting on a node gives one.
    return np.where(weight > 0, weight, 1e-300), ok


def least_route(graph: GridGraph, weight: NDArray, ok: NDArray
                ) -> tuple[list[int], float] | None:
    """Return the nodes start -> goal of least total weight over the `ok` edges, and it.

    None where the goal cannot be reached.
    """
    m = len(graph.nodes)
    mat = coo_matrix((weight[ok], (graph.edge_a[ok], graph.edge_b[ok])), shape=(m, m)).tocsr()
    dist, pred = dijkstra(mat, directed=False, indices=graph.start, return_predecessors=True)
    if not np.isfinite(dist[graph.goal]):
        return None
    seq = [graph.goal]
    while seq[-1] != graph.start:
        seq.append(int(pred[seq[-1]]))
    return seq[::-1], float(dist[graph.goal])


def route_points(graph: GridGraph, seq: Sequence[int]) -> NDArray:
    """Return the nodes of a route [m] without repeated points."""
    pts = graph.nodes[seq]
    keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])
    return pts[keep]


def grid_floor(graph: GridGraph, threats: ThreatField, w: float
               ) -> tuple[NDArray, float, float, float]:
    """Least-J path on the grid by Dijkstra.

    Parameters
    ----------
    graph : GridGraph
        From :func:`build_grid`.
    threats : ThreatField
        The same threats, to score the path.
    w : float
        Threat weight.

    Returns
    -------
    path : ndarray, shape (k, 3)
        Start, grid nodes, goal [m].
    J : float
        ``path_cost(path).J``.
    graph_J : float
        Dijkstra's distance (sum of edge J), equal to J up to rounding.
    seconds : float
        Search time (excluding the graph build).
    """
    t0 = time.perf_counter()
    weight, ok = edge_weights(graph, w)
    route = least_route(graph, weight, ok)
    if route is None:
        raise RuntimeError('grid floor: goal unreachable')
    pts = route_points(graph, route[0])
    seconds = time.perf_counter() - t0
    j = path_cost(pts, threats.positions, threats.intensities, w).J
    return pts, j, route[1], seconds
