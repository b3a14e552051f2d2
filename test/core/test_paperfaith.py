"""Issue 11: the paper's network, Fig. 11 entry/exit candidates, paths in the box, seeds."""

from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
import yaml

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.network.partition import build_network, paper_network
from threat_planner.core.network.search import nearest_nodes, spread_nodes
from threat_planner.core.network.seeds import (_unit_lattice, surface_lattice, surface_routes,
                                               VOLUME_ROUTES, volume_routes)
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.world.threats import Box
from threat_planner.errors import PlanningError

DATA = Path(__file__).resolve().parents[1] / 'data'
BUNDLED = sorted(p.stem for p in DATA.glob('*.yaml'))
BOX = Box.from_corners([0, 0, 0], [100, 100, 100])


@pytest.fixture(scope='module')
def uniform():
    return load_scenario(DATA / 'uniform20_0.yaml')


def _inside(points, box):
    return np.all(points >= box.lo - 1e-9) and np.all(points <= box.hi + 1e-9)


def test_paper_network_is_threats_only_and_plans(uniform):
    r = plan(uniform.threats, uniform.start, uniform.goal, uniform.box,
             PlannerConfig(method='paper', network='threats'))
    net = r.network
    assert net.n_threat_vertices == len(net.vertices) == len(uniform.threats)
    # The start is outside the threats' hull: it joins the nearest node, as in the paper.
    assert r.entry == int(nearest_nodes(net, uniform.start, 1)[0])
    th = uniform.threats
    assert r.cost.J == pytest.approx(path_cost(r.path, th.positions, th.intensities, 0.5).J,
                                     rel=1e-12)
    assert _inside(r.initial_path, uniform.box) and _inside(r.path, uniform.box)


@pytest.mark.parametrize('positions', [
    np.column_stack([np.random.default_rng(0).uniform(0, 100, (12, 2)), np.zeros(12)]),
    np.array([[float(i), 2.0 * i, 3.0 * i] for i in range(8)]),
], ids=['plane', 'line'])
def test_paper_network_refuses_flat_threats_naming_qhulls_flat_simplex(positions):
    with pytest.raises(PlanningError, match='QH6154'):
        paper_network(positions, BOX)
    # The box-covered network takes the same input.
    assert build_network(positions, BOX).n_nodes > 0


def test_paper_network_refuses_fewer_than_four_threats():
    with pytest.raises(PlanningError, match='at least 4 distinct threats, got 3'):
        paper_network(np.array([[1.0, 2, 3], [4, 5, 6], [7, 8, 1], [1.0, 2, 3]]), BOX)


def test_cli_flat_threats_on_the_paper_network_exit_2_with_one_line(tmp_path):
    sc = yaml.safe_load((DATA / 'uniform20_0.yaml').read_text())
    for t in sc['threats']:
        t['position'][2] = 0.0
    path = tmp_path / 'flat.yaml'
    path.write_text(yaml.safe_dump(sc))
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'plan', str(path),
                        '--method', 'paper', '--network', 'threats'],
                       capture_output=True, text=True)
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1 and 'QH6154' in p.stderr
    assert 'Traceback' not in p.stderr


def test_spread_candidates_are_distinct_real_cells_ahead_of_the_start(uniform):
    net = build_network(uniform.threats.positions, uniform.box)
    s, t = uniform.start, uniform.goal
    for k in (1, 3, 5):
        idx = spread_nodes(net, s, t, k)
        assert len(set(idx.tolist())) == len(idx) == k
        assert np.all((net.tetrahedra[idx] < net.n_threat_vertices).any(axis=1))
        assert np.all((net.nodes[idx] - s) @ (t - s) > 0)
        d = np.linalg.norm(net.nodes[idx] - s, axis=1)
        assert np.all(np.diff(d) >= 0)
    # The K nearest include a flat margin sliver (inradius at jitter level); spread do not.
    sliver = 1e-4 * uniform.box.diagonal
    assert np.any(net.radii[nearest_nodes(net, s, 3)] < sliver)
    assert np.all(net.radii[spread_nodes(net, s, t, 3)] > sliver)


def test_table_one_cells_are_not_all_equal_on_uniform20_0(uniform):
    r = plan(uniform.threats, uniform.start, uniform.goal, uniform.box,
             PlannerConfig(w=0.5, k=1000.0, method='improved', n_points=20))
    cells = {round(j, 1) for j in r.candidates.values()}
    assert len(r.candidates) == 9 and len(cells) > 1


@pytest.mark.parametrize('name', BUNDLED)
@pytest.mark.parametrize('method', ['paper', 'best'])
def test_initial_path_and_network_nodes_lie_in_the_box(name, method):
    sc = load_scenario(DATA / f'{name}.yaml')
    r = plan(sc.threats, sc.start, sc.goal, sc.box,
             PlannerConfig(method=method, n_points=20, max_pitch_deg=90.0,
                           max_turn_deg=180.0))
    assert _inside(r.network.nodes, sc.box)
    assert _inside(r.initial_path, sc.box) and _inside(r.path, sc.box)
    assert np.allclose(r.initial_path[[0, -1]], [sc.start, sc.goal])


def test_surface_lattice_edges_are_every_face_neighbour_pair():
    box = Box.from_corners([0, -5, 10], [40, 20, 30])
    n = 3
    pts, edges = surface_lattice(box, n)
    cells = np.rint((pts - box.lo) / (box.hi - box.lo) * n).astype(int)
    expected = set()
    for i in range(len(cells)):
        for j in range(i + 1, len(cells)):
            step = np.abs(cells[i] - cells[j])
            mid = (cells[i] + cells[j]) / 2
            if step.max() == 1 and np.any((mid == 0) | (mid == n)):
                expected.add((i, j))
    assert {tuple(sorted(e)) for e in edges.tolist()} == expected


@pytest.mark.parametrize('name', ['uniform20_0', 'ground_0', 'big300_0'])
def test_surface_routes_run_from_start_to_goal_over_the_box_surface(name):
    sc = load_scenario(DATA / f'{name}.yaml')
    routes = surface_routes(sc.threats, sc.start, sc.goal, sc.box, 0.5)
    assert 1 <= len(routes) <= 2
    for line in routes:
        assert np.allclose(line[0], sc.start) and np.allclose(line[-1], sc.goal)
        assert _inside(line, sc.box)
        inner = line[1:-1]
        on_face = np.isclose(inner, sc.box.lo) | np.isclose(inner, sc.box.hi)
        assert np.all(on_face.any(axis=1))
    assert not any(np.array_equal(routes[0], r) for r in routes[1:])


def test_volume_lattice_edges_are_every_neighbour_pair_once():
    n = 3
    cells, edges = _unit_lattice(n, surface=False)
    expected = {(i, j) for i in range(len(cells)) for j in range(i + 1, len(cells))
                if np.abs(cells[i] - cells[j]).max() == 1}
    got = [tuple(sorted(e)) for e in edges.tolist()]
    assert len(got) == len(set(got)) and set(got) == expected


def test_volume_routes_run_from_start_to_goal_through_the_box_and_differ():
    # The fresh field whose optimum crosses a sparse corner of the cloud (seeds.py).
    sc = load_scenario(DATA / 'inbox_regressions'
                       / 'inbox_s1796561117_uniform_n1000_f0_w0p2_off.yaml')
    routes = volume_routes(sc.threats, sc.start, sc.goal, sc.box, 0.2)
    assert len(routes) == VOLUME_ROUTES
    assert not any(np.array_equal(a, b) for i, a in enumerate(routes) for b in routes[:i])
    for line in routes:
        assert np.allclose(line[0], sc.start) and np.allclose(line[-1], sc.goal)
        assert _inside(line, sc.box)
    # Off the surface: the lattice's inner points carry the route.
    inner = np.vstack([line[1:-1] for line in routes])
    on_face = np.isclose(inner, sc.box.lo) | np.isclose(inner, sc.box.hi)
    assert not np.all(on_face.any(axis=1))


def test_surface_seed_wins_on_the_dense_field_and_beats_the_network_routes():
    """The in-box optimum (no flight limits) climbs along the box; with limits, no loss."""
    sc = load_scenario(DATA / 'big300_0.yaml')
    off = dict(max_climb_deg=90.0, max_dive_deg=90.0, min_turn_radius_m=0.0)
    for limited in (False, True):
        cfg = dict(w=0.5, max_pitch_deg=90.0, max_turn_deg=180.0, **({} if limited else off))
        with_seeds = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(**cfg))
        without = plan(sc.threats, sc.start, sc.goal, sc.box,
                       PlannerConfig(surface_seeds=False, **cfg))
        if limited:
            assert with_seeds.feasible
            assert with_seeds.cost.J <= without.cost.J * (1 + 1e-9)
        else:
            assert with_seeds.seed.startswith('surface route')
            assert with_seeds.cost.J < without.cost.J
