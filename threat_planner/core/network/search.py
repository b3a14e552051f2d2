"""Search on the network (paper Section 3.3 and Section IV Cases 1-2): Dijkstra.

The paper's "former" algorithm weighs each edge by its length; the "improved" one by the
edge's own cost J (eq. 15), which the closed-form threat integral makes cheap. Start and goal
are not network nodes: the paper joins them to the nearest node; Case 1 compares several
entry and exit candidates, which we do either pair by pair or, in one search, by adding the
start and goal as extra vertices joined to every candidate by their straight-line cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from threat_planner.core import _scipy_first  # noqa: F401,I100 (before any scipy)
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from threat_planner.core._vector import rows_dot, vector_length
from threat_planner.core.cost.kernels import segment_costs as compiled_costs
from threat_planner.core.cost.near_kernels import near_segment_costs
from threat_planner.core.network.graph_kernels import Graph
from threat_planner.core.network.partition import Network
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import PlanningError

#: Exact (segment x threat) pairs evaluated before edge costs switch to the cut-off.
DENSE_PAIR_LIMIT = 500_000
#: Cut-off radius for edge threat costs, in multiples of the threats' typical spacing.
CUTOFF_SPACINGS = 1.5


@dataclass(frozen=True)
class EdgeCosts:
    """Threat cost J_R of every network edge, and how far a cut-off may have lowered it.

    Attributes:
        threat: J_R of each edge, (E,).
        bound: Largest J_R the cut-off may have left out of each edge, (E,); zeros if
            every threat was counted.
        radius: Cut-off radius used [m], or None when exact.
        tail_per_metre: Mean-field estimate of what the dropped threats add per metre of
            edge: threats spread evenly at intensity density rho beyond the radius R add
            4 pi rho / R per metre. Uniform, so it only restores the balance between
            length and threat that the cut-off tilts; 0 when exact.
    """

    threat: NDArray
    bound: NDArray
    radius: float | None
    tail_per_metre: float = 0.0

    def combine(self, threat: NDArray, lengths: NDArray, w: float) -> NDArray:
        """J = w J_R + (1 - w) L of segments costed like these edges (same cut-off)."""
        return w * (threat + self.tail_per_metre * lengths) + (1.0 - w) * lengths

    def weights(self, lengths: NDArray, w: float) -> NDArray:
        """Edge weights J for the J-weighted Dijkstra (paper Case 2)."""
        return self.combine(self.threat, lengths, w)


def segment_costs(a: NDArray, b: NDArray, threats: ThreatField,
                  radius: float | None = None) -> tuple[NDArray, NDArray]:
    """J_R of each segment, exact or cut off at ``radius``, with the cut-off's bound.

    Args:
        a: Segment starts, (S, 3) [m].
        b: Segment ends, (S, 3) [m].
        threats: The threat field.
        radius: Cut-off distance [m]; None counts every threat.

    Returns:
        ``(costs (S,), bound (S,))``.
    """
    if radius is None or len(threats) == 0:
        return (compiled_costs(a, b, threats.positions, threats.intensities),
                np.zeros(len(a)))
    return near_segment_costs(a, b, threats.positions, threats.intensities, radius)


def edge_threat_costs(network: Network, threats: ThreatField, box_spacing: float,
                      exact: bool | None = None, volume: float | None = None) -> EdgeCosts:
    """Threat cost of every network edge (closed form, eq. 17).

    Args:
        network: The incentre network.
        threats: The threat field.
        box_spacing: Typical threat spacing [m], which scales the cut-off radius.
        exact: Count every threat (True), cut off (False), or decide by problem size (None).
        volume: Volume the threats fill [m^3], for the cut-off's mean-field tail.

    Returns:
        The EdgeCosts.
    """
    a = network.nodes[network.edges[:, 0]]
    b = network.nodes[network.edges[:, 1]]
    if exact is None:
        exact = len(a) * len(threats) <= DENSE_PAIR_LIMIT
    radius = None if exact else CUTOFF_SPACINGS * box_spacing
    costs, bound = segment_costs(a, b, threats, radius)
    tail = 0.0
    if radius is not None and volume:
        tail = 4.0 * np.pi * threats.total_intensity / volume / radius
    return EdgeCosts(costs, bound, radius, tail)


def nearest_nodes(network: Network, point: NDArray, k: int) -> NDArray:
    """Return the k nodes nearest to a point (entry or exit candidates), nearest first.

    Args:
        network: The network.
        point: Query point (3,) [m].
        k: How many candidates.

    Returns:
        Node indices, (min(k, M),).
    """
    return network.nearest(point, max(1, k))


def spread_nodes(network: Network, point: NDArray, toward: NDArray, k: int) -> NDArray:
    """Return k entry (or exit) candidates spread around a point, as the paper's Fig. 11.

    The paper picks "by eye" nodes near the start that are neither too far away nor too
    close to a threat. Here: nodes of cells with at least one threat vertex (the margin's
    all-auxiliary slivers have no inradius and smooth to the same path) lying towards
    ``toward``; the space around the axis point -> toward is split into k equal sectors,
    starting upwards, and each sector gives its node nearest the point. Sectors without a
    node are filled by the nearest remaining nodes.

    Args:
        network: The network.
        point: The start (or goal) (3,) [m].
        toward: The goal (or start) (3,) [m], which fixes the axis and the forward side.
        k: How many candidates.

    Returns:
        Node indices, (min(k, M),), nearest first.
    """
    k = max(1, min(k, network.n_nodes))
    real = (network.tetrahedra < network.n_threat_vertices).any(axis=1) & (network.radii > 0)
    pool = np.flatnonzero(real) if real.sum() >= k else np.arange(network.n_nodes)
    rel = network.nodes[pool] - point
    dist = np.linalg.norm(rel, axis=1)
    axis = np.asarray(toward, float) - point
    length = vector_length(axis)
    if length > 0:
        axis = axis / length
        ahead = rows_dot(rel, axis) > 0
        if ahead.sum() >= k:
            pool, rel, dist = pool[ahead], rel[ahead], dist[ahead]
    else:
        axis = np.array([1.0, 0.0, 0.0])
    # Sector 0 starts at the world's up direction seen across the axis (x if the axis is up).
    up = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = up - float(rows_dot(up, axis)) * axis
    e1 /= vector_length(e1)
    e2 = np.cross(axis, e1)
    phi = np.mod(np.arctan2(rows_dot(rel, e2), rows_dot(rel, e1)) + np.pi / k, 2 * np.pi)
    sector = np.minimum((phi / (2 * np.pi / k)).astype(np.int64), k - 1)
    order = np.argsort(dist, kind='stable')
    chosen: list[int] = []
    for j in range(k):
        in_j = order[sector[order] == j]
        if len(in_j):
            chosen.append(int(in_j[0]))
    for i in order:
        if len(chosen) == k:
            break
        if int(i) not in chosen:
            chosen.append(int(i))
    chosen.sort(key=lambda i: dist[i])
    return pool[np.array(chosen, dtype=np.int64)]


def entry_candidates(network: Network, point: NDArray, toward: NDArray, k: int,
                     how: str) -> NDArray:
    """Entry (or exit) candidates by ``how``: 'spread' (:func:`spread_nodes`) or 'nearest'."""
    if how == 'nearest':
        return nearest_nodes(network, point, k)
    return spread_nodes(network, point, toward, k)


def _graph(n: int, edges: NDArray, weights: NDArray) -> csr_matrix:
    # csgraph drops explicit zeros as "no edge", so coincident nodes get a tiny positive cost.
    wt = np.maximum(weights, 1e-12)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return csr_matrix((np.concatenate([wt, wt]), (rows, cols)), shape=(n, n))


def _walk_back(pred: NDArray, source: int, target: int) -> list[int]:
    seq = [target]
    while seq[-1] != source:
        prev = int(pred[seq[-1]])
        if prev < 0:
            raise PlanningError(f'network: node {target} is not reachable from node {source}')
        seq.append(prev)
    return seq[::-1]


def dijkstra_pairs(network: Network, weights: NDArray, entries: NDArray,
                   exits: NDArray) -> dict[tuple[int, int], tuple[list[int], float]]:
    """Least-weight node sequence for every (entry, exit) pair (paper Section 3.3).

    Args:
        network: The network.
        weights: Edge weights, (E,) (length for the paper's algorithm, J for the improved).
        entries: Entry candidate nodes.
        exits: Exit candidate nodes.

    Returns:
        ``{(entry, exit): (node sequence, total weight)}`` for the reachable pairs.
    """
    g = _graph(network.n_nodes, network.edges, weights)
    dist, pred = dijkstra(g, directed=False, indices=entries, return_predecessors=True)
    out = {}
    for r, s in enumerate(entries):
        for t in exits:
            if np.isfinite(dist[r, t]):
                out[(int(s), int(t))] = (_walk_back(pred[r], int(s), int(t)), float(dist[r, t]))
    return out


def dijkstra_with_terminals(network: Network, weights: NDArray, start_costs: NDArray,
                            entries: NDArray, goal_costs: NDArray, exits: NDArray
                            ) -> tuple[list[int], float]:
    """One Dijkstra over the network plus start and goal joined to their candidates.

    Args:
        network: The network.
        weights: Edge weights, (E,).
        start_costs: Weight of the straight leg from the start to each entry, (K,).
        entries: Entry candidate nodes, (K,).
        goal_costs: Weight of the straight leg from each exit to the goal, (K',).
        exits: Exit candidate nodes, (K',).

    Returns:
        ``(node sequence without start and goal, total weight)``.

    Raises:
        PlanningError: if no exit is reachable from any entry.
    """
    graph = _terminal_graph(network, entries, exits)
    return _route(graph, network.n_nodes,
                  np.concatenate([weights, start_costs, goal_costs]))


def _terminal_graph(network: Network, entries: NDArray, exits: NDArray) -> Graph:
    """Return the network plus the start (node m) and goal (m + 1) joined to candidates."""
    m = network.n_nodes
    edges = np.concatenate([network.edges,
                            np.stack([np.full(len(entries), m), entries], axis=1),
                            np.stack([exits, np.full(len(exits), m + 1)], axis=1)])
    return Graph(m + 2, edges)


def _route(graph: Graph, m: int, weights: NDArray) -> tuple[list[int], float]:
    """Least-weight route from the start (node m) to the goal (m + 1), ends dropped."""
    dist, pred = graph.shortest(weights, m, m + 1)
    if not np.isfinite(dist[m + 1]):
        raise PlanningError('network: the goal is not reachable from the start')
    return _walk_back(pred, m, m + 1)[1:-1], float(dist[m + 1])


def alternative_routes(network: Network, weights: NDArray, start_costs: NDArray,
                       entries: NDArray, goal_costs: NDArray, exits: NDArray, count: int,
                       penalty: float = 3.0) -> list[list[int]]:
    """Up to ``count`` distinct routes: the best, then each next with used edges penalised.

    Different routes usually pass different sides of the threats, i.e. lie in different
    basins of J, which a local optimiser cannot cross; trying several is cheap insurance.

    Args:
        network: The network.
        weights: Edge weights, (E,).
        start_costs: Weight of the start's legs to ``entries``.
        entries: Entry candidate nodes.
        goal_costs: Weight of the goal's legs from ``exits``.
        exits: Exit candidate nodes.
        count: Most routes returned.
        penalty: Factor applied to the weight of every edge already used.

    Returns:
        Node sequences, best first, without repeats.
    """
    w = np.array(weights, float)
    m = network.n_nodes
    keys = network.edges[:, 0] * m + network.edges[:, 1]
    order = np.argsort(keys)
    graph = _terminal_graph(network, entries, exits)
    legs = np.concatenate([start_costs, goal_costs])
    routes: list[list[int]] = []
    for _ in range(max(1, 2 * count)):
        seq, _ = _route(graph, m, np.concatenate([w, legs]))
        if seq not in routes:
            routes.append(seq)
            if len(routes) == count:
                break
        if len(seq) < 2:
            break
        s = np.asarray(seq)
        used = np.minimum(s[:-1], s[1:]) * m + np.maximum(s[:-1], s[1:])
        w[order[np.searchsorted(keys, used, sorter=order)]] *= penalty
    return routes
