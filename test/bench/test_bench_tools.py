"""Fast tests of the benchmark's own pieces (bench/toolkit/)."""

import importlib
import json
from pathlib import Path
import sys

import numpy as np
import pytest

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.world.threats import Box, ThreatField

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parents[1] / 'data'
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
bt = importlib.import_module('bench.toolkit.ompl_planners')
bg = importlib.import_module('bench.toolkit.grid')
bc = importlib.import_module('bench.toolkit.cases')

needs_ompl = pytest.mark.skipif(not bt.ompl_available(), reason='ompl cannot import')


def _rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


@pytest.fixture(scope='module')
def scenario():
    return load_scenario(DATA / 'uniform20_0.yaml')


def test_load_reference_parses_keys(tmp_path):
    path = tmp_path / 'reference.json'
    path.write_text(json.dumps({'a_b@0.2': {'J': 1.5, 'seconds': 2.0},
                                'x@0.8': {'J': 3.0}}))
    ref = bc.load_reference(path)
    assert ref[('a_b', 0.2)] == {'J': 1.5, 'seconds': 2.0}
    assert ref[('x', 0.8)]['J'] == 3.0
    assert np.isnan(ref[('x', 0.8)]['seconds'])


def test_load_reference_bundled():
    ref = bc.load_reference(DATA / 'reference.json')
    assert ('uniform20_0', 0.8) in ref
    assert len(ref) == 3 * len({name for name, _ in ref})
    assert all(v['J'] > 0 for v in ref.values())


def test_load_reference_rejects_bad_key(tmp_path):
    path = tmp_path / 'reference.json'
    path.write_text(json.dumps({'nokey': {'J': 1.0}}))
    with pytest.raises(ValueError):
        bc.load_reference(path)


@pytest.mark.parametrize('w', [0.2, 0.8])
def test_segment_cost_equals_path_cost(scenario, w):
    pos, f = scenario.threats.positions, scenario.threats.intensities
    seg = bt.SegmentCost(pos, f, w)
    rng = np.random.default_rng(3)
    for k in range(300):
        a, b = rng.uniform(0.0, 100.0, size=(2, 3))
        if k % 3 == 0:   # aim at a threat: near-line pairs, beyond and before it
            p = pos[rng.integers(len(pos))]
            b = a + (p - a) * rng.choice([0.5, 0.9999, 1.0001, 2.0]) + rng.normal(0, 1e-7, 3)
        expected = path_cost(np.array([a, b]), pos, f, w).J
        assert _rel(seg(a, b), expected) < 1e-9
    assert seg.calls == 300
    assert seg(np.ones(3), np.ones(3)) == 0.0


def test_grid_floor_path_and_cost(scenario):
    th = scenario.threats
    graph = bg.build_grid(th, scenario.start, scenario.goal, scenario.box, n=7)
    for w in (0.2, 0.8):
        pts, j, graph_j, _ = bg.grid_floor(graph, th, w)
        np.testing.assert_array_equal(pts[0], scenario.start)
        np.testing.assert_array_equal(pts[-1], scenario.goal)
        assert j == path_cost(pts, th.positions, th.intensities, w).J
        assert _rel(graph_j, j) < 1e-9
        assert np.all(pts >= scenario.box.lo) and np.all(pts <= scenario.box.hi)


def test_grid_floor_start_on_a_node():
    th = ThreatField.from_arrays([[50.0, 50.0, 50.0]], [1e5])
    box = Box.from_corners([0, 0, 0], [100, 100, 100])
    start, goal = np.array([0.0, 0.0, 50.0]), np.array([100.0, 100.0, 50.0])
    graph = bg.build_grid(th, start, goal, box, n=5)
    pts, j, graph_j, _ = bg.grid_floor(graph, th, 0.5)
    assert np.all(np.linalg.norm(np.diff(pts, axis=0), axis=1) > 0)
    np.testing.assert_array_equal(pts[[0, -1]], [start, goal])
    assert _rel(graph_j, j) < 1e-9


def test_scale_problem_density():
    for n in (20, 160):
        th, start, goal, box = bc.scale_problem(n, seed=1)
        assert len(th) == n
        side = box.hi[0] - box.lo[0]
        assert side == pytest.approx(100.0 * (n / 20) ** (1 / 3))
        assert box.contains(start) and box.contains(goal)
    a = bc.scale_problem(50, seed=2)[0].positions
    np.testing.assert_array_equal(a, bc.scale_problem(50, seed=2)[0].positions)


@needs_ompl
def test_ompl_motion_cost_equals_path_cost(scenario):
    th = scenario.threats
    prob = bt.ompl_problem(th, scenario.start, scenario.goal, scenario.box, 0.5)
    rng = np.random.default_rng(4)
    for _ in range(20):
        a, b = rng.uniform(0.0, 100.0, size=(2, 3))
        s1, s2 = bt._state(prob.space, a), bt._state(prob.space, b)
        got = prob.objective.motionCost(s1, s2).value()
        assert _rel(got, path_cost(np.array([a, b]), th.positions, th.intensities, 0.5).J) < 1e-9
        heur = prob.objective.motionCostHeuristic(s1, s2).value()
        assert heur == pytest.approx(0.5 * np.linalg.norm(b - a)) and heur <= got
    assert prob.objective.stateCost(s1).value() == 0.0


@needs_ompl
def test_ompl_planner_uses_our_motion_cost(scenario):
    th = scenario.threats
    bt.set_ompl_quiet()
    # Wall-clock budgets: at 0.2 s RRT* once found no exact path beside the suite's other
    # worker on a loaded machine (a fresh-clone CI run); this claims the cost, not speed.
    runs = bt.run_ompl('RRTstar', th, scenario.start, scenario.goal, scenario.box, 0.8,
                       [0.6, 1.2])
    assert [r['budget_s'] for r in runs] == [0.6, 1.2]
    for r in runs:
        assert r['exact'] and r['motion_calls'] > 0
        assert r['rel_diff'] < 1e-6
        pts = np.array(r['path'])
        np.testing.assert_allclose(pts[[0, -1]], [scenario.start, scenario.goal])
        assert r['J'] == path_cost(pts, th.positions, th.intensities, 0.8).J
    assert runs[1]['J'] <= runs[0]['J'] + 1e-12


def _case(name, w, n, js, ms=10.0, limits_ok=True, limited=110.0):
    """A benchmark case with in-box yardstick 100 and limited yardstick ``limited``."""
    methods = {k: {'J': j, 'ratio': j / 100.0, 'ms': ms, 'in_box': True,
                   'timings_ms': {'total_ms': ms}} for k, j in js.items()}
    for k, m in methods.items():
        if '@' in k:
            m.update(rel_diff=0.0, motion_calls=100, budget_s=1.0, capped=False)
    br = importlib.import_module('bench.toolkit.benchmark_report')
    if br.ON in methods:
        methods[br.ON].update(limits_ok=limits_ok, ratio_limited=methods[br.ON]['J'] / limited,
                              worst_violation='' if limits_ok else 'max_climb_deg 31 vs 30')
    return {'scenario': name, 'w': w, 'n_threats': n, 'methods': methods,
            'yardsticks': {'in_box': 100.0, 'in_box_source': 'bench 41^3', 'box_check': 1.0,
                           'limited': limited, 'lower_bound': 95.0,
                           'limits': {'max_climb_deg': 30.0, 'max_dive_deg': 30.0,
                                      'min_turn_radius_m': 10.0}}}


def test_targets_are_against_the_in_box_and_limited_yardsticks():
    br = importlib.import_module('bench.toolkit.benchmark_report')
    rb = importlib.import_module('bench.suites.benchmark')
    assert rb.OURS[br.OFF]['max_climb_deg'] == 90 and rb.OURS[br.OFF]['min_turn_radius_m'] == 0
    cases = [_case('a', 0.2, 20, {br.OFF: 100.1, br.ON: 111.0, 'RRT*@10x': 120.0}, ms=12.0),
             _case('b', 0.8, 20, {br.OFF: 103.0, br.ON: 110.0, 'RRT*@10x': 101.0}, ms=50.0,
                   limits_ok=False)]
    rows = {r['target']: r for r in br.evaluate_targets(cases, {'cli_ratio': 9.0,
                                                                'cli_ratio_note': 'x'})}
    med = rows[f'{br.OFF}: median J / in-box yardstick <= {br.MEDIAN_IN_BOX}']
    assert med['value'] == pytest.approx(1.0155) and med['verdict'] == 'MISS'
    worst = rows[f'{br.OFF}: worst J / in-box yardstick <= {br.WORST_IN_BOX}']
    assert worst['value'] == pytest.approx(1.03) and 'b@0.8' in worst['note']
    assert rows[f'{br.ON}: feasible (in the box, within the limits) on every case'][
        'value'] == 1
    lim = rows[f'{br.ON}: worst J / limited yardstick <= {br.WORST_LIMITED}']
    assert lim['value'] == pytest.approx(111.0 / 110.0) and lim['verdict'] == 'PASS'
    assert rows[f'{br.ON}: ~20 threats worst <= 40 ms']['verdict'] == 'MISS'
    assert rows[f'{br.ON}: ~20 threats median <= 15 ms']['value'] == pytest.approx(31.0)
    assert rows[f'{br.OFF} J < RRT*@10x J on every case']['verdict'] == 'MISS'
    assert rows['threat-planner plan, 10,000-threat YAML <= 8x bare Delaunay'][
        'verdict'] == 'MISS'
    assert rows[f'{br.ON}: 10,000 threats plan() <= 1.5 s']['verdict'] == 'n/a'
    summary = br.summary_table(cases)
    assert f'| {br.OFF} | yes | none | 2 |' in summary
    assert '| lower bound `reference.json` (leaves the box) | no | none | 2 | 0.9500' in summary
    assert 'NO (max_climb_deg 31 vs 30)' in br.cases_table(cases)


def test_random_fields_are_reproducible_and_the_summary_lists_the_movers():
    """The same 45 fields every run; a J moved past 0.2 % or an infeasible plan is listed."""
    rf = importlib.import_module('bench.suites.random_fields')
    first = [(name, th.positions.copy(), s, t) for name, th, s, t, _, _ in rf.fields()]
    again = list(rf.fields())
    assert len(first) == len(rf.SIZES) * len(rf.SEEDS) * len(rf.WS) == 45
    for (name, pos, s, t), (name2, th, s2, t2, box, _) in zip(first, again):
        assert name == name2
        np.testing.assert_array_equal(pos, th.positions)
        np.testing.assert_array_equal(s, s2)
        assert box.contains(s) and box.contains(t)
    before = {'a on': [100.0, 10.0, True], 'b on': [100.0, 10.0, True],
              'c on': [100.0, 10.0, True], 'a off': [90.0, 5.0, True]}
    after = {'a on': [100.1, 8.0, True], 'b on': [99.0, 8.0, True],
             'c on': [100.0, 8.0, False], 'a off': [90.0, 4.0, True]}
    line, rows = rf._summary(before, after, 'on')
    assert '3 plans' in line and 'worst 1.0010' in line and 'infeasible after: 1' in line
    assert [r.split(' |')[0] for r in rows] == ['| b on', '| c on']


def test_moved_threats_stay_within_the_fraction_of_the_diagonal():
    """The warm-replan move: every threat within 0.5 % of the diagonal, same seed same
    field, intensities untouched."""
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    diag = sc.box.diagonal
    moved = bc.moved_threats(sc.threats, diag)
    shift = np.linalg.norm(moved.positions - sc.threats.positions, axis=1)
    assert shift.max() <= 0.005 * diag and shift.min() > 0
    np.testing.assert_array_equal(moved.intensities, sc.threats.intensities)
    np.testing.assert_array_equal(bc.moved_threats(sc.threats, diag).positions,
                                  moved.positions)


def test_before_after_airspace_cases_are_every_airspace_scenario_at_one_weight():
    ba = importlib.import_module('bench.suites.before_after')
    air = ba.cases(airspace=True)
    names = sorted(f.stem for f in DATA.glob('air_*.yaml'))
    assert len(names) >= 6
    assert [(c['name'], c['limits_label']) for c in air] == [
        (f'{n}@0.5', label) for n in names for label in ('on', 'off')]
    assert all(load_scenario(c['file']).airspace is not None for c in air)
    plain = ba.cases()
    assert not any('air_' in c['name'] for c in plain)
    assert [c['threats'] for c in plain if 'threats' in c] == [1000, 10000]
