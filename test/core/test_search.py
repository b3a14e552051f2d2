"""Dijkstra on the network (paper Section 3.3, Cases 1-2)."""

import networkx as nx
import numpy as np
import pytest

from threat_planner.core.network.partition import build_network
from threat_planner.core.network.search import (alternative_routes, dijkstra_pairs,
                                                dijkstra_with_terminals, edge_threat_costs,
                                                nearest_nodes)
from threat_planner.core.world.threats import Box, ThreatField

BOX = Box.from_corners([0, 0, 0], [100, 100, 100])


@pytest.fixture(scope='module')
def net():
    return build_network(np.random.default_rng(0).uniform(0, 100, (25, 3)), BOX)


def test_dijkstra_matches_networkx(net):
    rng = np.random.default_rng(1)
    weights = rng.uniform(0.5, 2.0, net.n_edges) * net.edge_lengths
    g = nx.Graph()
    g.add_weighted_edges_from((int(a), int(b), float(wt))
                              for (a, b), wt in zip(net.edges, weights))
    entries, exits = np.array([0, 5]), np.array([net.n_nodes - 1, 7])
    got = dijkstra_pairs(net, weights, entries, exits)
    for (s, t), (seq, cost) in got.items():
        assert cost == pytest.approx(nx.dijkstra_path_length(g, s, t))
        assert seq[0] == s and seq[-1] == t
        assert sum(g[a][b]['weight'] for a, b in zip(seq[:-1], seq[1:])) == pytest.approx(cost)


def test_terminals_search_picks_the_cheapest_entry_exit_combination(net):
    weights = net.edge_lengths
    entries, exits = np.array([1, 2, 3]), np.array([10, 11])
    start_costs, goal_costs = np.array([5.0, 0.0, 9.0]), np.array([3.0, 50.0])
    seq, total = dijkstra_with_terminals(net, weights, start_costs, entries, goal_costs, exits)
    pairs = dijkstra_pairs(net, weights, entries, exits)
    brute = min(start_costs[list(entries).index(s)] + c + goal_costs[list(exits).index(t)]
                for (s, t), (_, c) in pairs.items())
    assert total == pytest.approx(brute)
    assert seq[0] in entries and seq[-1] in exits


def test_nearest_nodes_are_sorted_by_distance(net):
    p = np.array([10.0, 20.0, 30.0])
    idx = nearest_nodes(net, p, 5)
    d = np.linalg.norm(net.nodes[idx] - p, axis=1)
    assert np.all(np.diff(d) >= 0)
    assert d[0] == pytest.approx(np.min(np.linalg.norm(net.nodes - p, axis=1)))


@pytest.mark.parametrize('k', [1, 5, 40, 10_000])
def test_nearest_nodes_are_the_k_nearest_by_brute_force(net, k):
    rng = np.random.default_rng(k)
    for p in rng.uniform(-20, 120, (10, 3)):
        idx = net.nearest(p, k)
        d = np.linalg.norm(net.nodes - p, axis=1)
        assert len(idx) == min(k, net.n_nodes) and len(set(idx.tolist())) == len(idx)
        assert np.all(np.diff(d[idx]) >= 0)
        # None left out is nearer than the farthest kept.
        rest = np.setdiff1d(np.arange(net.n_nodes), idx)
        assert len(rest) == 0 or d[rest].min() >= d[idx].max()


def test_alternative_routes_are_distinct_and_best_first(net):
    routes = alternative_routes(net, net.edge_lengths, np.zeros(1), np.array([0]),
                                np.zeros(1), np.array([net.n_nodes - 1]), 4)
    assert 2 <= len(routes) <= 4
    assert len({tuple(r) for r in routes}) == len(routes)
    first = dijkstra_pairs(net, net.edge_lengths, np.array([0]), np.array([net.n_nodes - 1]))
    assert routes[0] == first[(0, net.n_nodes - 1)][0]


def test_cut_off_edge_costs_stay_within_their_stated_bound():
    rng = np.random.default_rng(2)
    threats = ThreatField.from_arrays(rng.uniform(0, 300, (700, 3)), rng.uniform(1e5, 3e5, 700))
    box = Box.from_corners([0, 0, 0], [300, 300, 300])
    net = build_network(threats.positions, box)
    exact = edge_threat_costs(net, threats, threats.typical_spacing(box), exact=True)
    cut = edge_threat_costs(net, threats, threats.typical_spacing(box), exact=False)
    assert cut.radius is not None and exact.radius is None
    missing = exact.threat - cut.threat
    assert np.all(missing >= -1e-9 * exact.threat)
    assert np.all(missing <= cut.bound * (1 + 1e-9))
