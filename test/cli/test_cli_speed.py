"""The cruise speed on the command line: it times the plan and changes no path."""

import json
import math
from pathlib import Path
import subprocess
import sys

import pytest

DATA = Path(__file__).resolve().parents[1] / 'data'
SCENARIO = DATA / 'uniform20_0.yaml'


def _run(*args):
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def _plan(tmp_path, name, *args, scenario=SCENARIO):
    out = tmp_path / f'{name}.json'
    p = _run('plan', scenario, '--json', out, *args)
    assert p.returncode == 0, p.stderr
    return json.loads(out.read_text()), p.stdout


@pytest.fixture(scope='module')
def default_plan(tmp_path_factory):
    return _plan(tmp_path_factory.mktemp('speed'), 'default')


def test_json_times_are_the_path_length_so_far_over_the_speed(default_plan):
    data, _ = default_plan
    path, t = data['path'], data['t']
    assert data['speed_mps'] == 20.0 and len(t) == len(path) and t[0] == 0.0
    flown = 0.0
    for k in range(1, len(path)):
        flown += math.dist(path[k - 1], path[k])
        assert t[k] == pytest.approx(flown / 20.0, rel=1e-12)
    assert data['eta_s'] == t[-1] > 0.0


def test_the_summary_prints_speed_and_eta(default_plan):
    data, stdout = default_plan
    line = next(x for x in stdout.splitlines() if x.strip().startswith('flight:'))
    assert line.strip() == (f"flight: 20 m/s, ETA {data['eta_s']:.1f} s over "
                            f"{20.0 * data['eta_s']:.1f} m")


def test_speed_changes_the_eta_but_not_the_path_bit_for_bit(tmp_path, default_plan):
    base, _ = default_plan
    slow, stdout = _plan(tmp_path, 'slow', '--speed', '5')
    assert slow['speed_mps'] == 5.0
    assert slow['eta_s'] == pytest.approx(4.0 * base['eta_s'], rel=1e-12)
    assert slow['t'] == pytest.approx([4.0 * t for t in base['t']], rel=1e-12)
    # JSON floats read back bit for bit: the same path and costs, to the last digit.
    for key in ('path', 'initial_path', 'cost', 'node_sequence', 'limits', 'path_limits'):
        assert slow[key] == base[key], key
    assert 'flight: 5 m/s' in stdout


def test_a_scenario_s_speed_is_used_and_speed_overrides_it(tmp_path, default_plan):
    fast = tmp_path / 'fast.yaml'
    fast.write_text(SCENARIO.read_text() + '\nspeed: 40\n')
    from_file, _ = _plan(tmp_path, 'file', scenario=fast)
    assert from_file['speed_mps'] == 40.0
    assert from_file['eta_s'] == pytest.approx(default_plan[0]['eta_s'] / 2.0, rel=1e-12)
    assert from_file['path'] == default_plan[0]['path']
    overridden, _ = _plan(tmp_path, 'cli', '--speed', '8', scenario=fast)
    assert overridden['speed_mps'] == 8.0


@pytest.mark.parametrize('value', ['0', '-3', 'nan', 'inf', '1001'])
def test_a_bad_speed_option_exits_2_with_one_line_naming_it(value):
    p = _run('plan', SCENARIO, '--speed', value)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in p.stderr
    assert 'speed_mps: must be finite and > 0 and <= 1000, got' in lines[0], lines[0]


@pytest.mark.parametrize('value, shown', [('0', '0'), ('-2.5', '-2.5'), ('.nan', 'nan'),
                                          ('.inf', 'inf'), ('fast', "'fast'")])
def test_a_bad_scenario_speed_exits_2_naming_the_file_the_key_and_the_value(
        tmp_path, value, shown):
    bad = tmp_path / 'bad.yaml'
    bad.write_text(SCENARIO.read_text() + f'\nspeed: {value}\n')
    p = _run('plan', bad)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert lines == [f'threat-planner: error: {bad}: speed: must be finite and > 0 and '
                     f'<= 1000 [m/s], got {shown}']


def test_the_help_lists_speed_with_its_default_and_unit():
    text = ' '.join(_run('plan', '--help').stdout.split())
    assert '--speed SPEED' in text and '[m/s]' in text and '(default: 20.0)' in text
