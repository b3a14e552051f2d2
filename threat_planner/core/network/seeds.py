"""Extra seeds for ``best``'s screening: least-J routes over coarse lattices of the box.

In a dense field the least-J path inside the box often hugs the box: up a vertical edge,
along the ceiling's edge, down the far edge, as far from the threat cloud as the box allows.
The incentre network's routes run between threats and rarely reach that basin, and a local
minimisation from them cannot cross the threats to get there. A coarse lattice on the box's
surface, 8-connected on every face, with each edge weighted by its J (closed form; in big
fields only threats within two typical spacings, with no far-field tail: the tail assumes
threats all around, while at the box's surface half the space is empty) gives a few surface
routes by Dijkstra; the screening then decides whether one of them wins.

Without flight limits a lattice through the whole box (26-connected, VOLUME_DIVISIONS per
edge) gives routes too: along a wall for a while, then across a sparse corner of the cloud,
a basin neither the network nor the surface reaches (a fresh 1,000-threat field at w 0.2:
643.5 against the surface route's 676.3, the in-box yardstick's 643.3).

With climb and dive limits a third lattice keeps to them: the surface one with knight's
steps on each face and no edge steeper than the limits (:func:`sloped_routes`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.network.graph_kernels import Graph
from threat_planner.core.network.search import segment_costs
from threat_planner.core.world.threats import Box, ThreatField

__all__ = ['sloped_routes', 'SURFACE_DIVISIONS', 'SURFACE_ROUTES', 'surface_lattice',
           'surface_routes', 'VOLUME_DIVISIONS', 'VOLUME_ROUTES', 'volume_routes']

#: Intervals per box edge of the surface lattice.
SURFACE_DIVISIONS = 8
#: Surface routes returned (each next one with the edges of earlier ones penalised).
SURFACE_ROUTES = 2
#: Intervals per box edge of the volume lattice, and its routes returned. At 8 the
#: 1,000-threat field of the module docstring found no new basin; at 12 it did, and on
#: three more fresh fields of 100-300 threats its routes refined to within 1.0007 of the
#: in-box yardstick where the other seeds ended 1.0098-1.0393 above it. The third route
#: found strongweak n1000 f1 w 0.2 of seed 1796638025 (620.2 against 631.2, the yardstick
#: 620.0); on a fresh seed's 180 limits-off cases it changed 13, none higher.
VOLUME_DIVISIONS = 12
VOLUME_ROUTES = 3
#: Lattice points the start and the goal are joined to.
TERMINAL_LEGS = 6
#: (edge, threat) pairs costed exactly before the lattice switches to the cut-off (by
#: default; the caller may allow more).
DENSE_PAIRS = 100_000
#: Cut-off radius of the lattice's edge costs, in typical threat spacings.
CUTOFF_SPACINGS = 2.0
#: Factor on the weight of edges an earlier route used.
ROUTE_PENALTY = 3.0


def surface_lattice(box: Box, divisions: int, reach: int = 1) -> tuple[NDArray, NDArray]:
    """Lattice on the box's surface and its edges that lie on a face.

    Args:
        box: The flight box.
        divisions: Intervals per box edge.
        reach: 2 adds the knight's steps of :func:`_unit_lattice`.

    Returns:
        ``(points (P, 3) [m], edges (E, 2))``: neighbours differ by at most one step per
        axis and share a face, so every edge runs on the surface (face diagonals included).
    """
    cells, edges = _unit_lattice(divisions, True, reach)
    return box.lo + cells / divisions * (box.hi - box.lo), edges


@lru_cache(maxsize=4)
def _unit_lattice(divisions: int, surface: bool = True, reach: int = 1
                  ) -> tuple[NDArray, NDArray]:
    """Return the lattice in integer cells 0..divisions per axis (read-only: shared).

    ``surface``: only the cells on the box's surface and the edges that lie on a face;
    else every cell and its 13 forward neighbours (26-connected). ``reach`` 2 adds the
    steps of two cells along one axis and one along another (:func:`sloped_routes`).
    """
    n = divisions
    ticks = np.arange(n + 1)
    grid = np.stack(np.meshgrid(ticks, ticks, ticks, indexing='ij'), axis=-1).reshape(-1, 3)
    kept = ((grid == 0) | (grid == n)).any(axis=1) if surface else np.ones(len(grid), bool)
    ids = np.full(len(grid), -1, dtype=np.int64)
    ids[kept] = np.arange(int(kept.sum()))
    cells = grid[kept]
    offsets = np.array([o for o in np.ndindex(3, 3, 3)]) - 1
    if reach == 2:
        # Knight's steps (2, 1) in the plane of two axes; their doubles are not edges.
        knight = [o for o in np.array(list(np.ndindex(5, 5, 5))) - 2
                  if sorted(np.abs(o)) == [0, 1, 2]]
        offsets = np.vstack([offsets, knight])
    offsets = offsets[[tuple(o) > (0, 0, 0) for o in offsets]]
    pairs = []
    for o in offsets:
        b = cells + o
        ok = np.all((b >= 0) & (b <= n), axis=1)
        if surface:
            # The edge lies on a face when an axis it does not move along is at 0 or n.
            ok &= np.any((o == 0) & ((cells == 0) | (cells == n)), axis=1)
        flat = (b[ok] * [(n + 1) ** 2, n + 1, 1]).sum(axis=1)
        dst = ids[flat]
        src = np.flatnonzero(ok)
        keep = dst >= 0
        pairs.append(np.stack([src[keep], dst[keep]], axis=1))
    edges = np.concatenate(pairs)
    cells.setflags(write=False)
    edges.setflags(write=False)
    return cells, edges


def volume_routes(threats: ThreatField, s: NDArray, t: NDArray, box: Box, w: float,
                  divisions: int = VOLUME_DIVISIONS, count: int = VOLUME_ROUTES,
                  dense_pairs: int | None = None) -> list[NDArray]:
    """Least-J routes from s to t over a 26-connected lattice through the whole box.

    Args and returns as :func:`surface_routes`.
    """
    cells, edges = _unit_lattice(divisions, surface=False)
    return _routes(box.lo + cells / divisions * (box.hi - box.lo), edges, threats, s, t, box,
                   w, count, dense_pairs)


def sloped_routes(threats: ThreatField, s: NDArray, t: NDArray, box: Box, w: float,
                  max_slope_deg: float, divisions: int = SURFACE_DIVISIONS,
                  count: int = SURFACE_ROUTES, dense_pairs: int | None = None
                  ) -> list[NDArray]:
    """Least-J routes over the box's surface, no lattice edge steeper than the limit.

    ``max_slope_deg`` [deg] bounds every edge's climb and dive. On a face the lattice
    also steps two cells along one axis and one along another (slopes of 26.6 deg on a
    cubic box's walls), and every edge steeper than the limit is dropped: a route down a
    wall then descends as a limited path may, where the surface routes
    (:func:`surface_routes`) drop down the box's vertical edges and hold to the limits far
    from there (uniform n1000 f0 w 0.8 of seed 1796561117: the ceiling route's limit-free
    optimum 371.5 held to 524.6, a wall descent at 30 deg to 489.6).
    Args and returns as :func:`surface_routes`, with the slope limit [deg].
    """
    points, edges = surface_lattice(box, divisions, reach=2)
    d = points[edges[:, 1]] - points[edges[:, 0]]
    rise = np.abs(d[:, 2])
    run = np.hypot(d[:, 0], d[:, 1])
    slope = np.tan(np.radians(min(max(max_slope_deg, 0.0), 90.0)))
    ok = rise <= slope * run + 1e-9 * (rise + run)
    return _routes(points, edges[ok], threats, s, t, box, w, count, dense_pairs)


def surface_routes(threats: ThreatField, s: NDArray, t: NDArray, box: Box, w: float,
                   divisions: int = SURFACE_DIVISIONS, count: int = SURFACE_ROUTES,
                   dense_pairs: int | None = None) -> list[NDArray]:
    """Least-J routes from s to t over the box's surface lattice, as polylines in the box.

    Args:
        threats: The threat field.
        s: Start (3,) [m], in the box.
        t: Goal (3,) [m], in the box.
        box: The flight box.
        w: Threat weight of J.
        divisions: Intervals per box edge of the lattice.
        count: Most routes returned.
        dense_pairs: Most (edge, threat) pairs costed exactly (default DENSE_PAIRS).

    Returns:
        Distinct polylines ``[s, lattice points..., t]`` (each (m, 3) [m]), best first.
    """
    points, edges = surface_lattice(box, divisions)
    return _routes(points, edges, threats, s, t, box, w, count, dense_pairs)


def _routes(points: NDArray, edges: NDArray, threats: ThreatField, s: NDArray, t: NDArray,
            box: Box, w: float, count: int, dense_pairs: int | None) -> list[NDArray]:
    """Distinct least-J routes over a lattice (earlier routes' edges penalised), best first."""
    m = len(points)
    k = min(TERMINAL_LEGS, m)
    legs = [np.atleast_1d(np.argsort(np.linalg.norm(points - p, axis=1))[:k]) for p in (s, t)]
    a = np.concatenate([points[edges[:, 0]], np.repeat(s[None], k, 0), points[legs[1]]])
    b = np.concatenate([points[edges[:, 1]], points[legs[0]], np.repeat(t[None], k, 0)])
    radius = None if len(a) * len(threats) <= (dense_pairs or DENSE_PAIRS) \
        else CUTOFF_SPACINGS * threats.typical_spacing(box)
    threat, _ = segment_costs(a, b, threats, radius)
    lengths = np.linalg.norm(b - a, axis=1)
    weights = w * threat + (1.0 - w) * lengths
    # Vertices m and m + 1 are the start and the goal.
    rows = np.concatenate([edges[:, 0], np.full(k, m), legs[1]])
    cols = np.concatenate([edges[:, 1], legs[0], np.full(k, m + 1)])
    weights = np.maximum(weights, 1e-12)
    keys = np.minimum(rows, cols) * (m + 2) + np.maximum(rows, cols)
    graph = Graph(m + 2, np.stack([rows, cols], axis=1))
    routes: list[NDArray] = []
    seqs: list[list[int]] = []
    for _ in range(2 * count):
        dist, pred = graph.shortest(weights, m, m + 1)
        if not np.isfinite(dist[m + 1]):
            break
        seq = [m + 1]
        while seq[-1] != m:
            seq.append(int(pred[seq[-1]]))
        seq.reverse()
        inner = seq[1:-1]
        if inner not in seqs:
            seqs.append(inner)
            routes.append(box.clip(np.vstack([s, points[inner], t])))
            if len(routes) == count:
                break
        a_, b_ = np.array(seq[:-1]), np.array(seq[1:])
        used = np.minimum(a_, b_) * (m + 2) + np.maximum(a_, b_)
        weights = np.where(np.isin(keys, used), weights * ROUTE_PENALTY, weights)
    return routes
