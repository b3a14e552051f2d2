"""The detection outputs of the command line (issue 43): the plan's print line, the
``--detection-plot`` figure and the ``paper`` command's detection table."""

import json
from pathlib import Path
import re
import subprocess
import sys

import numpy as np

DATA = Path(__file__).resolve().parents[1] / 'data'
PNG = b'\x89PNG\r\n\x1a\n'


def _run(*args):
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def _detection_lines(stdout):
    return [line for line in stdout.splitlines() if line.lstrip().startswith('detection:')]


def test_plan_prints_one_detection_line_matching_its_json_and_writes_the_figure(tmp_path):
    out, png = tmp_path / 'plan.json', tmp_path / 'detection.png'
    p = _run('plan', DATA / 'uniform20_0.yaml', '--n-points', '20', '--json', out,
             '--detection-plot', png)
    assert p.returncode == 0, p.stderr
    lines = _detection_lines(p.stdout)
    assert len(lines) == 1, p.stdout
    line = lines[0]
    d = json.loads(out.read_text())['detection']
    per = np.asarray(d['per_threat'])
    i = int(np.argmax(per))
    assert f"P_detect={d['P_detect']:.4g}" in line and f"H={d['H']:.4g}" in line
    assert f'(largest: threat {i}, {100 * per[i] / d["H"]:.1f} % of H)' in line
    # The model it is reported under: the defaults; a paper plan has no bound status.
    assert line.endswith(') swerling 1, rcs constant 1, p_fa 1e-06, T 1 s, v 20 m/s'), line
    data = png.read_bytes()
    assert data[:8] == PNG and len(data) > 10_000


def test_a_detection_plan_names_its_cost_and_model_and_draws_its_figure(tmp_path):
    png = tmp_path / 'sub' / 'det.png'   # a missing folder is made
    p = _run('plan', DATA / 'uniform20_0.yaml', '--n-points', '20', '--cost', 'detection',
             '--swerling', '0', '--rcs', 'ellipsoid 3 1 0.5', '--max-detection', '1e-12',
             '--detection-plot', png)
    assert p.returncode == 0, p.stderr
    line, = _detection_lines(p.stdout)
    # The model, then the bound's status: 1e-12 cannot be met on this field.
    assert ' swerling 0, rcs ellipsoid 3 1 0.5, p_fa 1e-06, T 1 s, v 20 m/s; status: unmet' in line
    assert png.read_bytes()[:8] == PNG


def test_dot_areas_follow_f():
    from threat_planner.cli.detection_figure import dot_sizes
    np.testing.assert_allclose(dot_sizes([1.0, 2.0, 4.0], 8.0, 160.0), [40.0, 80.0, 160.0])
    assert list(dot_sizes([0.001, 1.0], 8.0, 160.0)) == [8.0, 160.0]   # a floor, visible
    assert list(dot_sizes([0.0, 0.0], 8.0, 160.0)) == [8.0, 8.0]


def test_a_plan_without_the_option_writes_no_detection_figure(tmp_path):
    p = _run('plan', DATA / 'ground_0.yaml', '--n-points', '20')
    assert p.returncode == 0, p.stderr
    assert len(_detection_lines(p.stdout)) == 1
    assert not list(tmp_path.glob('*.png'))


def test_paper_adds_a_detection_table_where_the_detection_plan_wins_its_objective(tmp_path):
    p = _run('paper', DATA / 'weak20_0.yaml', '--out', tmp_path, '--n-points', '20')
    assert p.returncode == 0, p.stderr
    text = (tmp_path / 'tables.md').read_text()
    for where in (p.stdout, text):
        assert 'Detection: paper-cost plan (w=0.5) vs detection-cost plan (w=0.999)' in where
    section = text.split('## Detection:')[1].split('\n## ')[0]
    rows = {r[0]: r for r in (
        [c.strip() for c in line.strip('|').split('|')]
        for line in section.splitlines() if re.match(r'\| (paper|detection) \|', line))}
    assert set(rows) == {'paper', 'detection'}
    header, = [[c.strip() for c in line.strip('|').split('|')]
               for line in section.splitlines() if line.startswith('| cost minimised')]
    assert header[1:7] == ['w', 'P_detect', 'H', 'length [m]', 'J (w=0.5)',
                           'w H + (1 - w) L / L_0 (w=0.999)']
    assert rows['paper'][1] == '0.5' and rows['detection'][1] == '0.999 [1]'
    assert '[1] Not the paper\'s w = 0.5' in section   # the footnote on w
    for row in rows.values():
        p_detect, h = float(row[2]), float(row[3])
        assert 0 < p_detect < 1 and abs(p_detect - (1 - np.exp(-h))) <= 1e-3 * p_detect
        assert float(row[4]) > 0 and float(row[5]) > 0
    # The detection plan minimises w H + (1 - w) L / L_0: no worse there than the paper's.
    assert float(rows['detection'][6]) <= float(rows['paper'][6]) * (1 + 1e-6)
    assert 'Note: the detection plan' not in section
    # The paper's cost J is what the paper-cost plan minimises: no worse there either.
    assert float(rows['paper'][5]) <= float(rows['detection'][5]) * (1 + 1e-3)


def test_the_table_says_when_the_detection_plan_loses_its_own_objective():
    from threat_planner.cli.reproduction import detection_warning
    paper = {'cost': 'paper', 'objective': 0.00255}
    assert detection_warning([paper, {'cost': 'detection', 'objective': 0.00254}]) == ''
    note = detection_warning([paper, {'cost': 'detection', 'objective': 0.00344}])
    assert 'worse basin' in note and '0.00344' in note and '0.00255' in note
