"""Flight-space partition (paper Section 3.2): Delaunay tetrahedra and the incentre network.

The threats' 3-D Delaunay tetrahedralisation splits space into cells whose four vertices
are radars. Each cell's "safest node" is its incentre (the paper's Fig. 3 argument: the
circumcentre may lie outside the cell and next to another cell's radar, the incentre never
does), and two nodes are joined when their cells share a face.

Beyond the paper: the tetrahedralisation alone covers only the threats' convex hull, so a
route around the threat cloud would not exist, and ground radars at one altitude (or fewer
than four threats) are flat or empty input on which Qhull fails (QH6154). We therefore add
auxiliary vertices on the surface of the flight box, grown by a small margin: the cells then
tile the whole box, the point set is never flat, and 0 to 3 threats still give a network.
Auxiliary vertices carry no intensity; they only shape the cells. Nodes of cells in the
margin are projected onto the box (the cells and their adjacency stay as they are), so every
route on the network flies inside the box. :func:`paper_network` is the paper's network as
written: threats only, over their convex hull.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray
from threat_planner.core._scipy_first import unmasked  # noqa: I100 (before any scipy)
from scipy.spatial import cKDTree, Delaunay, QhullError

from threat_planner.core.network.graph_kernels import incentre_kernel
from threat_planner.core.world.threats import Box
from threat_planner.errors import PlanningError

#: Growth of the box, as a fraction of its diagonal, before auxiliary vertices go on it.
BOX_MARGIN = 0.02
#: Threats farther than this many box diagonals from the box are left out of the cells.
FAR_THREAT_DIAGONALS = 10.0
#: Threat positions closer than this fraction of the box diagonal are one vertex.
MERGE_TOLERANCE = 1e-7


@dataclass(frozen=True)
class Network:
    """The incentre network of a Delaunay tetrahedralisation.

    Attributes:
        vertices: Delaunay vertices, threats first then auxiliary box points, (V, 3) [m].
        n_threat_vertices: How many leading vertices are (merged) threat positions.
        tetrahedra: Vertex indices of each cell, (M, 4).
        nodes: Incentre of each cell, (M, 3) [m].
        radii: Inradius of each cell, (M,) [m].
        edges: Node pairs whose cells share a face, (E, 2), first index smaller.
    """

    vertices: NDArray
    n_threat_vertices: int
    tetrahedra: NDArray
    nodes: NDArray
    radii: NDArray
    edges: NDArray

    @property
    def n_nodes(self) -> int:
        """Number of nodes (cells)."""
        return len(self.nodes)

    @property
    def n_edges(self) -> int:
        """Number of network edges (shared faces)."""
        return len(self.edges)

    @cached_property
    def edge_lengths(self) -> NDArray:
        """Length of each network edge, (E,) [m]."""
        return np.linalg.norm(self.nodes[self.edges[:, 1]] - self.nodes[self.edges[:, 0]],
                              axis=1)

    def nearest(self, point: NDArray, k: int) -> NDArray:
        """Return the k nodes nearest to a point [m], nearest first (ties: lower number first).

        By brute force: a plan asks for two points' candidates, and a k-d tree of the
        66,000 nodes of 10,000 threats took 17 ms to build, the distances 1 ms.
        """
        d2 = ((self.nodes - np.asarray(point, float)) ** 2).sum(axis=1)
        k = max(0, min(int(k), len(d2)))
        some = np.argpartition(d2, k - 1)[:k] if 0 < k < len(d2) else np.arange(k)
        return some[np.lexsort((some, d2[some]))].astype(np.int64)

    def delaunay_edges(self) -> NDArray:
        """Return the tetrahedra's unique edges, (K, 2) indices into vertices."""
        t = self.tetrahedra
        pairs = np.concatenate([t[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])
        pairs.sort(axis=1)
        return np.unique(pairs, axis=0)

    def to_networkx(self) -> 'nx.Graph':  # noqa: F821
        """Return the network as a networkx graph (node attr ``pos``, edge attr ``length``).

        Returns:
            Undirected graph on node ids 0..M-1.
        """
        # Imported here: the planner does not need networkx, and it costs ~0.1 s to load.
        import networkx as nx
        g = nx.Graph()
        g.add_nodes_from((i, {'pos': tuple(p), 'radius': float(r)})
                         for i, (p, r) in enumerate(zip(self.nodes, self.radii)))
        g.add_edges_from((int(a), int(b), {'length': float(d)})
                         for (a, b), d in zip(self.edges, self.edge_lengths))
        return g


def incentres(corners: NDArray) -> tuple[NDArray, NDArray]:
    """Incentre and inradius of tetrahedra: the face-area-weighted mean of the vertices.

    Args:
        corners: Vertices of each tetrahedron, shape (M, 4, 3) [m].

    Returns:
        ``(centres (M, 3), radii (M,))``; radius = 3 * volume / total face area (a cell
        without volume has radius 0; one without area, its vertices' mean as centre).
    """
    corners = np.ascontiguousarray(corners, float)
    centres = np.empty((len(corners), 3))
    radii = np.empty(len(corners))
    # Compiled: numpy's dozen whole-array steps cost 0.26 ms on 175 cells, 47 ms on 65,000.
    incentre_kernel(corners, centres, radii)
    return centres, radii


def box_surface_points(box: Box, divisions: int) -> NDArray:
    """Lattice points on the surface of a box, ``divisions`` intervals per edge.

    Args:
        box: The box.
        divisions: Intervals per edge (1 gives the 8 corners).

    Returns:
        Array (P, 3) of points [m].
    """
    return box.lo + _unit_surface(divisions) * (box.hi - box.lo)


@lru_cache(maxsize=4)
def _unit_surface(divisions: int) -> NDArray:
    """Return the lattice on the unit cube's surface (read-only: shared)."""
    ticks = np.linspace(0.0, 1.0, divisions + 1)
    g = np.stack(np.meshgrid(ticks, ticks, ticks, indexing='ij'), axis=-1).reshape(-1, 3)
    out = g[np.any((g == 0.0) | (g == 1.0), axis=1)]
    out.setflags(write=False)
    return out


@lru_cache(maxsize=4)
def _jitter(count: int) -> NDArray:
    """Return the fixed jitter of ``count`` auxiliary points, in box diagonals (read-only)."""
    out = np.random.default_rng(0).uniform(-1e-6, 1e-6, (count, 3))
    out.setflags(write=False)
    return out


def merge_duplicates(positions: NDArray, tolerance: float) -> NDArray:
    """Positions with near-duplicates (closer than ``tolerance``) collapsed to one.

    Args:
        positions: Points, shape (N, 3) [m].
        tolerance: Merge distance [m].

    Returns:
        The distinct points, first occurrence kept, in input order.
    """
    if len(positions) < 2:
        return positions
    pairs = cKDTree(positions).query_pairs(tolerance, output_type='ndarray')
    if len(pairs) == 0:
        return positions
    keep = np.ones(len(positions), dtype=bool)
    keep[pairs.max(axis=1)] = False
    return positions[keep]


def build_network(positions: NDArray, box: Box, box_divisions: int = 2) -> Network:
    """Tetrahedralise threats plus the flight box's surface and build the incentre network.

    Args:
        positions: Threat positions, shape (N, 3) [m]; any N, duplicates and flat sets
            allowed.
        box: Flight box; the network tiles it (grown by BOX_MARGIN of its diagonal).
        box_divisions: Intervals per box edge for the auxiliary surface lattice.

    Returns:
        The Network.
    """
    diag = box.diagonal
    threat_pts = np.asarray(positions, float).reshape(-1, 3)
    centre = 0.5 * (box.lo + box.hi)
    # Threats many box sizes away shape no cell inside the box (the box's own surface
    # vertices separate them) but can wreck Qhull's precision; they still count in J.
    near = np.linalg.norm(threat_pts - centre, axis=1) <= FAR_THREAT_DIAGONALS * diag
    threat_pts = merge_duplicates(threat_pts[near], MERGE_TOLERANCE * diag)
    grown = Box(box.lo - BOX_MARGIN * diag, box.hi + BOX_MARGIN * diag)
    aux = box_surface_points(grown, box_divisions)
    # A lattice on a box is highly co-spherical, which makes the Delaunay cells ambiguous;
    # a fixed tiny jitter picks one tiling reproducibly.
    aux = aux + _jitter(len(aux)) * diag
    # Threats that sit on an auxiliary point (or outside the grown box) keep priority.
    keep_aux = cKDTree(threat_pts).query(aux)[0] > MERGE_TOLERANCE * diag \
        if len(threat_pts) else np.ones(len(aux), dtype=bool)
    return _tetrahedralise(np.concatenate([threat_pts, aux[keep_aux]]), len(threat_pts),
                           centre, box)


def paper_network(positions: NDArray, box: Box) -> Network:
    """Build the paper's network: Delaunay of the threat positions alone (Section 3.2).

    It covers only the threats' convex hull; a start or goal outside it joins the nearest
    nodes, as in the paper. Nodes are projected onto the box when threats lie outside it.

    Args:
        positions: Threat positions, shape (N, 3) [m]; duplicates are merged.
        box: Flight box.

    Returns:
        The Network.

    Raises:
        PlanningError: for fewer than 4 distinct threats, or all of them on one plane
            or line (Qhull's flat initial simplex, QH6154).
    """
    diag = box.diagonal
    pts = merge_duplicates(np.asarray(positions, float).reshape(-1, 3),
                           MERGE_TOLERANCE * diag)
    if len(pts) < 4:
        raise PlanningError(f"network 'threats': the paper's network needs at least 4 "
                            f"distinct threats, got {len(pts)}; use network 'box'")
    centred = pts - pts.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[2] <= 1e-9 * max(float(sv[0]), 1e-300):
        raise PlanningError(f"network 'threats': the {len(pts)} threats lie on one plane, "
                            "so Qhull's initial simplex is flat (QH6154); use network 'box'")
    return _tetrahedralise(pts, len(pts), box=box)


def bare_network(positions: NDArray) -> Network:
    """Build the paper's network exactly: Delaunay of the threats alone, no box (Figs. 4-7).

    Args:
        positions: Threat positions, shape (N >= 4, 3), not all on one plane [m].

    Returns:
        The Network over the threats' convex hull.
    """
    vertices = np.asarray(positions, float)
    return _tetrahedralise(vertices, len(vertices))


def _tetrahedralise(vertices: NDArray, n_threat_vertices: int,
                    centre: NDArray | None = None, box: Box | None = None) -> Network:
    """Delaunay cells of the vertices, their incentres and face-adjacency edges.

    With a box, nodes outside it are projected onto it: a route joins the same cells but
    never leaves the flight box.
    """
    # Qhull works in absolute coordinates: a small box far from the origin loses every
    # digit of its size unless the points are centred first.
    shift = vertices.mean(axis=0) if centre is None else centre
    local = vertices - shift
    try:
        with unmasked():
            tri = Delaunay(local, qhull_options='Qbb Qc Qz Q12 Qt')
    except QhullError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else 'QhullError'
        raise PlanningError(f'partition: Qhull cannot tetrahedralise these points ({first})'
                            ) from None
    tets = tri.simplices.astype(np.int64)
    nodes, radii = incentres(local[tets])
    nodes = nodes + shift
    if box is not None:
        nodes = box.clip(nodes)
    src = np.repeat(np.arange(len(tets)), 4)
    dst = tri.neighbors.reshape(-1)
    mask = dst > src
    edges = np.stack([src[mask], dst[mask]], axis=1).astype(np.int64)
    return Network(vertices, n_threat_vertices, tets, nodes, radii, edges)
