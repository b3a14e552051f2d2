"""``threat-planner fly`` and ``--start-heading``: outputs, JSON keys, figure, bad input."""

import json
import math
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from threat_planner.cli import main
from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.optimise.limits import check_limits, FlightLimits

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / 'test' / 'data' / 'uniform20_0.yaml'
#: The example of docs/flight.md: a pop-up, a move, a removal and a new goal.
EVENTS = ROOT / 'examples' / 'flight' / 'popup.yaml'
#: The keys the issue asks OUT.json for, and the ones fly adds beside them.
ISSUE_KEYS = {'flown', 'replans', 'J_flown', 'J_hindsight', 'max_jump_m', 'reached_goal'}
MORE_KEYS = {'scenario', 'events_file', 'commit_s', 'w', 'start_heading', 'speed_mps',
             'flown_cost', 'hindsight_cost', 'hindsight_path', 'max_tracking_m', 'goal_miss_m',
             'flown_limits', 'lethal_entries'}


def _run(*args):
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope='module')
def flown(tmp_path_factory):
    out = tmp_path_factory.mktemp('fly')
    p = _run('fly', SCENARIO, '--events', EVENTS, '--speed', '18', '--commit', '1.5',
             '--start-heading', '45', '0', '--json', out / 'flight.json', '--plot',
             out / 'fig' / 'flight.png')
    assert p.returncode == 0, p.stderr
    return out, p.stdout, json.loads((out / 'flight.json').read_text())


def test_the_json_holds_the_issue_s_keys_and_the_flight(flown):
    _, _, data = flown
    assert set(data) == ISSUE_KEYS | MORE_KEYS
    t, path = data['flown']['t'], data['flown']['path']
    assert len(t) == len(path) > 10 and all(len(p) == 3 for p in path)
    assert t[0] == 0.0 and max(np.diff(t)) <= 0.1 + 1e-9
    assert [r['reason'] for r in data['replans']] == [
        'start', 'add_threat at t=2', 'move_threat #10 at t=2.5', 'remove_threat #3 at t=3',
        'goal at t=3.5']
    for r in data['replans']:
        assert {'t', 'latency_ms', 'reason'} <= set(r)
    assert data['replans'][1]['t'] == pytest.approx(2.0)
    assert data['speed_mps'] == 18.0 and data['commit_s'] == 1.5
    assert data['start_heading'] == pytest.approx([math.sqrt(0.5), math.sqrt(0.5), 0.0])
    assert data['J_flown'] == data['flown_cost']['J'] > 0
    assert data['J_hindsight'] == data['hindsight_cost']['J'] > 0
    assert isinstance(data['reached_goal'], bool)
    assert data['scenario'] == 'uniform20_0' and data['events_file'] == str(EVENTS)


def test_the_summary_names_replans_costs_jump_goal_and_limits(flown):
    _, stdout, data = flown
    lines = stdout.splitlines()
    assert lines[0].startswith('uniform20_0: flew ') and '18 m/s (commit 1.5 s)' in lines[0]
    assert sum(line.strip().startswith('replan t=') for line in lines) == 5
    assert any(line.strip().startswith('replan t=2.00 s (add_threat at t=2): ')
               and ' ms, ' in line for line in lines)
    ratio = data['J_flown'] / data['J_hindsight']
    cost = next(line for line in lines if 'J_flown=' in line)
    assert f"J_flown={data['J_flown']:.3f}" in cost and f'ratio {ratio:.4f}' in cost
    assert any(f"max_jump_m={data['max_jump_m']:.3f}" in line
               and f"reached_goal={data['reached_goal']}" in line for line in lines)
    assert any(line.strip().startswith('flown limits: climb ') for line in lines)


def test_the_plot_is_a_png(flown):
    out, _, _ = flown
    png = out / 'fig' / 'flight.png'
    assert png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


@pytest.mark.parametrize('args, message', [
    (['--start-heading', '1', '2'], None),                       # two numbers: yaw pitch
    (['--start-heading', '0', '0', '0'], 'start_heading: a zero vector has no direction'),
    (['--start-heading', '1', 'nan', '0'], 'start_heading: expected [x, y, z] or '
                                           '[yaw_deg, pitch_deg], finite, got [1.0, nan'),
    (['--start-heading', '1', '2', '3', '4'], 'start_heading: expected [x, y, z] or'),
    (['--start-heading', 'north'], "argument --start-heading: invalid float value: 'north'"),
    (['--events', 'missing.yaml'], 'events: cannot read missing.yaml'),
])
def test_bad_options_exit_2_with_one_line(tmp_path, args, message):
    (tmp_path / 'ev.yaml').write_text('events: [{t: 1.0, goal: [500, 0, 0]}]\n')
    full = ['fly', SCENARIO, '--events', tmp_path / 'ev.yaml', *args]
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, full)],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 2 and 'Traceback' not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1
    # The heading is good in the first case: the goal outside the box is what stops it.
    assert (message or 'events[0].goal: [500.0, 0.0, 0.0] is outside bounds') in lines[0]


def _plan(tmp_path, capsys, *args):
    out = tmp_path / 'plan.json'
    assert main(['plan', str(SCENARIO), '--json', str(out), *map(str, args)]) == 0
    return json.loads(out.read_text()), capsys.readouterr().out


@pytest.mark.parametrize('heading, unit', [
    (['0', '1', '0'], [0.0, 1.0, 0.0]),
    (['90', '10'], [0.0, math.cos(math.radians(10)), math.sin(math.radians(10))]),
])
def test_plan_leaves_along_the_start_heading_and_costs_that_path(tmp_path, capsys, heading,
                                                                 unit):
    data, stdout = _plan(tmp_path, capsys, '--start-heading', *heading)
    assert data['start_heading'] == pytest.approx(unit, abs=1e-15)
    path = np.array(data['path'])
    first = (path[1] - path[0]) / np.linalg.norm(path[1] - path[0])
    assert first == pytest.approx(unit, abs=1e-9)
    sc, cfg = load_scenario(SCENARIO), PlannerConfig()
    exact = path_cost(path, sc.threats.positions, sc.threats.intensities, cfg.w)
    assert data['cost']['final']['J'] == pytest.approx(exact.J, rel=1e-12)
    in_box = bool(np.all((path >= 0) & (path <= 100)))
    limits_met = check_limits(path, FlightLimits.of(cfg), 0.0).feasible
    assert data['entry_feasible'] is (in_box and limits_met)
    # The plan turned: the heading is not its own first direction.
    assert data['entry_turn_deg'] > 1.0
    assert data['t'][-1] == pytest.approx(data['eta_s'])
    assert data['eta_s'] == pytest.approx(sum(np.linalg.norm(np.diff(path, axis=0), axis=1))
                                          / 20.0, rel=1e-12)
    line = next(x for x in stdout.splitlines() if x.strip().startswith('start heading:'))
    assert f"first turn {data['entry_turn_deg']:.1f} deg" in line
    assert f"feasible={data['entry_feasible']}" in line
    final = next(x for x in stdout.splitlines() if x.strip().startswith('final:'))
    assert f"J={data['cost']['final']['J']:.3f}" in final


def test_plan_without_the_heading_has_none_of_its_keys(tmp_path, capsys):
    data, stdout = _plan(tmp_path, capsys)
    assert not {'start_heading', 'entry_turn_deg', 'entry_feasible'} & set(data)
    assert 'start heading' not in stdout


def test_plan_along_its_own_first_direction_keeps_its_path(tmp_path, capsys):
    base, _ = _plan(tmp_path, capsys)
    path = np.array(base['path'])
    own = path[1] - path[0]
    data, _ = _plan(tmp_path, capsys, '--start-heading', *own.tolist())
    assert data['entry_turn_deg'] < 1e-6 and data['entry_vertices_moved'] == 0
    assert data['path'] == base['path']
    # The same path, costed once by the plan and once after the (null) entry: to rounding.
    for part in ('initial', 'final'):
        assert data['cost'][part] == pytest.approx(base['cost'][part], rel=1e-13)


def test_plan_refuses_the_heading_with_a_robust_plan(capsys):
    assert main(['plan', str(SCENARIO), '--start-heading', '1', '0', '0', '--robust',
                 '2']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['threat-planner: error: start_heading: not with --robust (it would '
                   'describe the path before the heading)']


def test_a_straight_flight_writes_strict_json_with_null_for_no_turn(tmp_path, capsys):
    """A straight flight has no turn radius (inf in the report): null in OUT.json."""
    (tmp_path / 'line.yaml').write_text(
        'bounds: {min: [0, 0, 0], max: [100, 100, 100]}\nstart: [0, 0, 50]\n'
        'goal: [100, 100, 50]\nthreats:\n  - {position: [50, 90, 10], intensity: 1.0}\n')
    (tmp_path / 'none.yaml').write_text('events: []\n')
    out = tmp_path / 'out.json'
    assert main(['fly', str(tmp_path / 'line.yaml'), '--events', str(tmp_path / 'none.yaml'),
                 '--json', str(out)]) == 0
    assert 'turn radius none' in capsys.readouterr().out
    data = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(c))
    assert data['flown_limits']['min_turn_radius_m'] is None
    assert data['reached_goal'] is True and len(data['replans']) == 1
