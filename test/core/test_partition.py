"""Flight-space partition (paper Section 3.2): Delaunay cells, incentres, network."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from threat_planner.core.network.partition import (bare_network, box_surface_points, build_network,
                                                   incentres, merge_duplicates)
from threat_planner.core.world.threats import Box

BOX = Box.from_corners([0, 0, 0], [100, 100, 100])


def _face_distances(corners, point):
    out = []
    for i in range(4):
        a, b, c = (corners[j] for j in range(4) if j != i)
        n = np.cross(b - a, c - a)
        out.append(abs(np.dot(point - a, n)) / np.linalg.norm(n))
    return np.array(out)


def test_incentre_is_inside_and_equidistant_from_the_four_faces():
    rng = np.random.default_rng(0)
    tets = rng.uniform(0, 10, (50, 4, 3))
    centres, radii = incentres(tets)
    for corners, c, r in zip(tets, centres, radii):
        assert _face_distances(corners, c) == pytest.approx(np.full(4, r), rel=1e-9)
        # Inside: non-negative barycentric coordinates.
        t = np.column_stack([corners[1:] - corners[0]]).T
        lam = np.linalg.solve(t, c - corners[0])
        assert np.all(lam >= -1e-12) and lam.sum() <= 1 + 1e-12


def test_a_flat_cell_has_no_inradius_and_a_point_cell_its_point():
    """Four coplanar corners: radius 0, centre still inside; four equal ones: that point."""
    flat = [[0.0, 0, 0], [4, 0, 0], [0, 4, 0], [1, 1, 0]]
    point = [[2.0, 3, 4]] * 4
    c, r = incentres(np.array([flat, point]))
    assert r[0] == 0.0 and c[0, 2] == 0.0 and 0 < c[0, 0] < 4 and 0 < c[0, 1] < 4
    assert r[1] == 0.0 and c[1].tolist() == [2.0, 3.0, 4.0]


def test_circumcentre_may_leave_the_cell_but_incentre_does_not():
    # A flat "sliver" whose circumcentre is far outside (the paper's Fig. 3 argument).
    corners = np.array([[[0.0, 0, 0], [10, 0, 0], [5, 1, 0], [5, 0.5, 0.2]]])
    c, _ = incentres(corners)
    assert np.all(c[0] >= corners[0].min(axis=0)) and np.all(c[0] <= corners[0].max(axis=0))


def test_four_threats_give_one_node_and_no_edge():
    net = bare_network(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]))
    assert (net.n_nodes, net.n_edges) == (1, 0)


def test_five_threats_in_a_bipyramid_give_two_nodes_and_one_edge():
    pts = np.array([[0.0, 0, 0], [2, 0, 0], [1, 2, 0], [1, 0.7, 2], [1, 0.7, -2]])
    net = bare_network(pts)
    assert (net.n_nodes, net.n_edges) == (2, 1)
    shared = set(net.tetrahedra[0]) & set(net.tetrahedra[1])
    assert len(shared) == 3


def test_network_edges_join_cells_that_share_a_face():
    rng = np.random.default_rng(1)
    net = build_network(rng.uniform(0, 100, (30, 3)), BOX)
    for a, b in net.edges:
        assert len(set(net.tetrahedra[a]) & set(net.tetrahedra[b])) == 3
    g = net.to_networkx()
    assert g.number_of_nodes() == net.n_nodes and g.number_of_edges() == net.n_edges


def test_network_covers_the_whole_box():
    rng = np.random.default_rng(2)
    net = build_network(rng.uniform(30, 70, (20, 3)), BOX)
    tri = Delaunay(net.vertices)
    probes = np.vstack([rng.uniform(0, 100, (500, 3)), box_surface_points(BOX, 1)])
    assert np.all(tri.find_simplex(probes) >= 0)
    # Routes around the threat cloud exist: some nodes lie outside the threats' hull.
    assert np.any(Delaunay(net.vertices[:net.n_threat_vertices]).find_simplex(net.nodes) < 0)


@pytest.mark.parametrize('positions', [
    np.zeros((0, 3)),
    np.array([[50.0, 50, 50]]),
    np.array([[10.0, 10, 10], [90, 90, 90], [10, 90, 50]]),
    np.column_stack([np.random.default_rng(3).uniform(0, 100, (20, 2)), np.zeros(20)]),
    np.array([[1.0, 2, 3]] * 6 + [[4.0, 5, 6]] * 3),
    np.array([[float(i), 2 * i, 3 * i] for i in range(10)]),
], ids=['none', 'one', 'three', 'ground-plane', 'duplicates', 'collinear'])
def test_degenerate_threat_sets_still_give_a_connected_network(positions):
    net = build_network(positions, BOX)
    assert net.n_nodes > 0
    g = net.to_networkx()
    import networkx as nx
    assert nx.is_connected(g)


def test_duplicates_and_near_duplicates_are_merged():
    pts = np.array([[1.0, 1, 1], [1.0, 1, 1 + 1e-9], [5.0, 5, 5], [1.0, 1, 1]])
    assert len(merge_duplicates(pts, 1e-6)) == 2
    net = build_network(pts, BOX)
    assert net.n_threat_vertices == 2
