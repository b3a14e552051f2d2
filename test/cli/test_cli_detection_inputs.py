"""The detection model's settings on the command line (issue 43).

A scenario's ``detection`` block stands in for the defaults as its ``speed`` does, an
option overrides it; a bad value exits 2 with one line and no traceback; ``plan --help``
lists every option with its default.
"""

import json
from pathlib import Path
import subprocess
import sys

import pytest

from threat_planner.cli.main import build_parser, main
from threat_planner.cli.options import config_from
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario

DATA = Path(__file__).resolve().parents[1] / 'data'
SCENARIO = DATA / 'uniform20_0.yaml'
BLOCK = """
detection:
  cost: detection
  max_detection: 0.2
  speed: 30
  scan_period: 2.0
  p_fa: 1.0e-4
  swerling: 0
  rcs: {ellipsoid: [3.0, 1.0, 0.5]}
"""


def _run(*args):
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def _scenario(tmp_path, extra, name='radar.yaml'):
    path = tmp_path / name
    path.write_text(SCENARIO.read_text() + extra)
    return path


def _config(path, *options):
    args = build_parser().parse_args(['plan', str(path), *options])
    return config_from(args, load_scenario(path))


def test_the_scenario_s_block_stands_in_for_the_defaults(tmp_path):
    cfg = _config(_scenario(tmp_path, BLOCK))
    assert (cfg.cost_model, cfg.max_detection, cfg.speed_mps, cfg.scan_period_s, cfg.p_fa,
            cfg.swerling, cfg.rcs) == ('detection', 0.2, 30.0, 2.0, 1.0e-4, 0,
                                       'ellipsoid 3.0 1.0 0.5')
    # What the block leaves out keeps its default.
    only = _config(_scenario(tmp_path, '\ndetection: {p_fa: 0.01}\n', 'only.yaml'))
    assert only == PlannerConfig(p_fa=0.01)


def test_options_override_the_scenario_s_block(tmp_path):
    cfg = _config(_scenario(tmp_path, BLOCK), '--cost', 'paper', '--max-detection', '1',
                  '--speed', '12', '--scan-period', '0.5', '--p-fa', '0.001',
                  '--swerling', '1', '--rcs', 'constant 4')
    assert (cfg.cost_model, cfg.max_detection, cfg.speed_mps, cfg.scan_period_s, cfg.p_fa,
            cfg.swerling, cfg.rcs) == ('paper', 1.0, 12.0, 0.5, 0.001, 1, 'constant 4')


def test_a_scenario_s_detection_cost_with_method_paper_is_refused(tmp_path, capsys):
    path = _scenario(tmp_path, '\ndetection: {cost: detection}\n')
    assert main(['plan', str(path), '--method', 'paper']) == 2
    err = capsys.readouterr().err
    assert err == ("threat-planner: error: cost_model: detection needs method best, got "
                   "method 'paper' (set method best, or cost_model paper)\n")


def _hazard(tmp_path, scenario, *options):
    out = tmp_path / f'{len(list(tmp_path.iterdir()))}.json'
    p = _run('plan', scenario, '--method', 'paper', '--json', out, *options)
    assert p.returncode == 0, p.stderr
    return json.loads(out.read_text())['detection']['H']


def test_the_scenario_s_scan_period_reaches_the_plan_and_the_option_overrides_it(tmp_path):
    # H = sum of the integrals of P_d ds / (v T): on the same path (cost paper), twice the
    # scan period halves it. The scenario's T = 2, then --scan-period 4.
    base = _hazard(tmp_path, SCENARIO)
    slow_scan = _scenario(tmp_path, '\ndetection: {scan_period: 2.0}\n')
    assert base > 0.0
    assert _hazard(tmp_path, slow_scan) == pytest.approx(base / 2.0, rel=1e-9)
    overridden = _hazard(tmp_path, slow_scan, '--scan-period', '4')
    assert overridden == pytest.approx(base / 4.0, rel=1e-9)


@pytest.mark.parametrize('option, value, message', [
    ('--swerling', '2', 'swerling: must be 0 or 1, got 2'),
    ('--p-fa', '0', 'p_fa: must satisfy 0 < p_fa < 1, got 0.0'),
    ('--p-fa', '1', 'p_fa: must satisfy 0 < p_fa < 1, got 1.0'),
    ('--scan-period', '0', 'scan_period_s: must be finite and > 0 and <= 3600, got 0.0'),
    ('--scan-period', '-2', 'scan_period_s: must be finite and > 0 and <= 3600, got -2.0'),
    ('--max-detection', '0', 'max_detection: must be finite and > 0 and <= 1, got 0.0'),
    ('--rcs', 'ellipsoid 1 2', 'rcs: ellipsoid takes 3 values, got 2'),
    ('--rcs', 'sphere 1', "rcs: kind must be one of constant, ellipsoid, got 'sphere'"),
    ('--speed', '0', 'speed_mps: must be finite and > 0 and <= 1000, got 0.0'),
])
def test_a_bad_option_exits_2_with_one_line_naming_the_setting(capsys, option, value, message):
    assert main(['plan', str(SCENARIO), option, value]) == 2
    assert capsys.readouterr().err == f'threat-planner: error: {message}\n'


@pytest.mark.parametrize('option, value, message', [
    ('--swerling', '0.5', "argument --swerling: invalid int value: '0.5'"),
    ('--cost', 'risk', "argument --cost: invalid choice: 'risk'"),
])
def test_an_option_argparse_refuses_exits_2_with_one_line(capsys, option, value, message):
    with pytest.raises(SystemExit) as done:
        main(['plan', str(SCENARIO), option, value])
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err


def test_a_bad_value_in_a_process_is_one_line_and_no_traceback(tmp_path):
    for args in (['--swerling', '2'], ['--p-fa', '0']):
        p = _run('plan', SCENARIO, *args)
        assert p.returncode == 2 and 'Traceback' not in p.stderr
        assert len(p.stderr.strip().splitlines()) == 1
    bad = _scenario(tmp_path, '\ndetection: {swerling: 2}\n')
    p = _run('plan', bad)
    assert p.returncode == 2 and p.stderr == (
        f'threat-planner: error: {bad}: detection.swerling: must be 0 or 1, got 2\n')


def test_plan_help_lists_the_options_with_their_defaults():
    text = ' '.join(_run('plan', '--help').stdout.split())
    for option, default in (('--cost {paper,detection}', 'paper'),
                            ('--max-detection MAX_DETECTION', '1.0'),
                            ('--scan-period SCAN_PERIOD', '1.0'), ('--p-fa P_FA', '1e-06'),
                            ('--swerling SWERLING', '1'), ('--rcs RCS', 'constant 1.0')):
        assert option in text, option
        start = text.index(option, text.index('options:'))
        assert f'(default: {default})' in text[start:start + 400], option
    assert "if not given, the scenario's detection.scan_period (default: 1.0)" in text
