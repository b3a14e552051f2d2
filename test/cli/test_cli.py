"""The ``threat-planner`` command line, run as a user runs it."""

import json
from pathlib import Path
import subprocess
import sys

import pytest

DATA = Path(__file__).resolve().parents[1] / 'data'


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=300, cwd=cwd)


def test_plan_prints_a_summary_and_writes_json_and_figure(tmp_path):
    out, png = tmp_path / 'plan.json', tmp_path / 'plan.png'
    p = _run('plan', DATA / 'uniform20_0.yaml', '--w', '0.3', '--json', out, '--plot', png)
    assert p.returncode == 0, p.stderr
    assert 'final:' in p.stdout and 'nodes' in p.stdout and 'ms' in p.stdout
    data = json.loads(out.read_text())
    assert set(data) >= {'initial_path', 'path', 'cost', 'network', 'entry', 'exit', 'k',
                         'feasible', 'timings_ms'}
    assert set(data['cost']['final']) == {'J', 'J_L', 'J_R'}
    assert data['w'] == 0.3 and data['method'] == 'best'
    assert f"J={data['cost']['final']['J']:.3f}" in p.stdout
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_outputs_into_a_missing_folder_create_it(tmp_path):
    # `make plan-demo` on a fresh clone: demo_out/ does not exist yet.
    out = tmp_path / 'demo_out'
    p = _run('plan', DATA / 'uniform20_0.yaml', '--json', out / 'plan.json',
             '--plot', out / 'plan.png')
    assert p.returncode == 0, p.stderr
    assert json.loads((out / 'plan.json').read_text())['method'] == 'best'
    assert (out / 'plan.png').is_file()


def test_an_output_path_the_system_refuses_exits_2_with_one_line(tmp_path):
    blocker = tmp_path / 'a_file'
    blocker.write_text('')
    p = _run('plan', DATA / 'uniform20_0.yaml', '--json', blocker / 'plan.json')
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and 'a_file' in lines[0] and 'Traceback' not in p.stderr


@pytest.mark.parametrize('method', ['paper', 'improved'])
def test_plan_methods_and_k_options(tmp_path, method):
    out = tmp_path / 'p.json'
    p = _run('plan', DATA / 'ground_0.yaml', '--method', method, '--k', '1500', '--json', out)
    assert p.returncode == 0, p.stderr
    data = json.loads(out.read_text())
    if method == 'paper':
        assert data['k'] == 1500


@pytest.mark.parametrize('args,needle', [
    (['plan', 'missing.yaml'], 'missing.yaml: cannot read'),
    (['plan', DATA / 'uniform20_0.yaml', '--w', '1.5'], 'w: must satisfy 0 < w < 1'),
    (['plan', DATA / 'uniform20_0.yaml', '--method', 'magic'], 'invalid choice'),
    (['plan'], 'required'),
    (['nonsense'], 'invalid choice'),
])
def test_user_errors_exit_2_with_one_line(args, needle):
    p = _run(*args)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0]
    assert 'Traceback' not in p.stderr


def test_bad_scenario_file_exits_2(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text((DATA / 'uniform20_0.yaml').read_text().replace('intensity: 164216.4',
                                                                   'intensity: -1'))
    p = _run('plan', bad)
    assert p.returncode == 2
    assert p.stderr.count('\n') == 1 and 'threats[0].intensity' in p.stderr


def test_paper_reproduction_writes_tables_and_figures(tmp_path):
    p = _run('paper', DATA / 'weak20_0.yaml', '--out', tmp_path, '--n-points', '20')
    assert p.returncode == 0, p.stderr
    text = (tmp_path / 'tables.md').read_text()
    for name in ('Table I', 'Table II', 'Table III', 'Case 3'):
        assert name in text and name in p.stdout
    # Table II and III have one row per w = 0.1 .. 0.9.
    assert text.count('| 0.1 |') >= 3 and text.count('| 0.9 |') >= 3
    pngs = sorted(f.name for f in tmp_path.glob('*.png'))
    assert pngs == ['fig12_w0.2.png', 'fig13_w0.5.png', 'fig14_w0.8.png', 'fig8_network.png',
                    'fig9_dijkstra.png']


def test_no_arguments_print_usage_and_subcommands_and_exit_2():
    proc = subprocess.run([sys.executable, '-m', 'threat_planner.cli'], capture_output=True,
                          text=True, cwd=str(DATA.parent.parent), timeout=60)
    assert proc.returncode == 2 and proc.stdout == ''
    assert proc.stderr.startswith('usage: threat-planner')
    for command in ('plan', 'paper', 'replay'):
        assert command in proc.stderr


def _console(prelude: str, *args) -> subprocess.CompletedProcess:
    """Run the script's entry point after ``prelude`` in a fresh interpreter."""
    code = (f'import sys\n{prelude}\nsys.argv = ["threat-planner", *{list(map(str, args))!r}]\n'
            'from threat_planner.cli.main import console\nconsole()\n')
    return subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=300)


def test_the_script_runs_exit_functions_and_flushes_before_it_skips_teardown(tmp_path):
    out = tmp_path / 'plan.json'
    p = _console('import atexit\natexit.register(print, "exit functions ran")',
                 'plan', DATA / 'uniform20_0.yaml', '--json', out)
    assert p.returncode == 0, p.stderr
    assert 'final:' in p.stdout and p.stdout.rstrip().endswith('exit functions ran')
    assert json.loads(out.read_text())['method'] == 'best'
    bad = _console('', 'plan', DATA / 'uniform20_0.yaml', '--n-points', '0')
    assert bad.returncode == 2 and bad.stderr.count('\n') == 1


def test_the_script_waits_for_a_running_thread_like_a_normal_exit():
    prelude = ('import threading, time\n'
               'threading.Thread(target=lambda: (time.sleep(1), print("thread done"))).start()')
    p = _console(prelude, 'plan', DATA / 'uniform20_0.yaml', '--method', 'paper')
    assert p.returncode == 0, p.stderr
    assert 'thread done' in p.stdout


def test_output_into_a_closed_pipe_is_no_traceback():
    script = subprocess.Popen([sys.executable, '-m', 'threat_planner.cli', 'plan',
                               str(DATA / 'uniform20_0.yaml')], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE)
    script.stdout.close()
    assert script.wait(timeout=300) == 1 and b'Traceback' not in script.stderr.read()
