"""``threat-planner batch`` and ``plan --robust`` as a user runs them."""

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
from study_harness import cli, DATA, ROOT, write_study

from threat_planner import load_scenario, path_cost
from threat_planner.core.robust import sample_pictures, Uncertainty


def test_batch_writes_the_table_and_the_report(tmp_path):
    study = write_study(tmp_path, scenarios=('weak20_0',), w=[0.3, 0.7],
                        uncertainty={'samples': 3, 'position_sigma_m': 5.0},
                        robust={'samples': 2})
    p = cli('batch', study, '--out', tmp_path / 'out', '--workers', '2')
    assert p.returncode == 0, p.stderr
    assert '4 tasks, 4 run now on local (2 workers)' in p.stdout and '16 rows' in p.stdout
    table = pq.read_table(tmp_path / 'out' / 'results.parquet')
    assert table.num_rows == 16
    report = (tmp_path / 'out' / 'report.md').read_text()
    assert '## J against w' in report and '## J under uncertainty' in report
    for png in ('j_vs_w.png', 'spread.png'):
        assert (tmp_path / 'out' / png).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
        assert f']({png})' in report
    nominal = [r['J'] for r in table.to_pylist()
               if r['plan'] == 'nominal' and r['sample'] is None]
    assert len(nominal) == 2
    assert all(f'{j:.4g}' in report for j in nominal)


WITHOUT_RAY = ("import sys; sys.modules['ray'] = None\n"
               "from threat_planner.cli.main import main; sys.exit(main(sys.argv[1:]))")


def test_ray_without_ray_installed_says_how_to_install_it(tmp_path):
    study = write_study(tmp_path, scenarios=('weak20_0',))
    p = subprocess.run([sys.executable, '-c', WITHOUT_RAY, 'batch', str(study), '--out',
                        str(tmp_path / 'out'), '--ray', 'auto'], capture_output=True,
                       text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'threat_planner[cluster]'" in lines[0]
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('args,needle', [
    (['--workers', '0'], '--workers: must be an integer >= 1, got 0'),
    (['--ray', ''], "--ray: give a cluster address or 'auto'"),
    (['--ray', '127.0.0.1:1'], '--ray: no Ray cluster answers at 127.0.0.1:1 (Connection '
                               'refused)'),
    (['--ray', 'nonsense'], "--ray: expected host:port or 'auto', got 'nonsense'"),
])
def test_bad_batch_options_exit_2_with_one_line(tmp_path, args, needle):
    study = write_study(tmp_path, scenarios=('weak20_0',))
    if args[0] == '--ray':
        pytest.importorskip('ray')
    p = cli('batch', study, '--out', tmp_path / 'out', *args)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [f'threat-planner: error: {needle}']
    assert not (tmp_path / 'out').exists()


def test_plan_loads_neither_pyarrow_nor_ray(tmp_path):
    probe = ('import sys, json\n'
             'from threat_planner.cli.main import main\n'
             f'code = main(["plan", {str(DATA / "weak20_0.yaml")!r}, "--json", '
             f'{str(tmp_path / "p.json")!r}])\n'
             'print(json.dumps(sorted(m for m in sys.modules '
             'if m.split(".")[0] in ("pyarrow", "ray"))))\n'
             'sys.exit(code)\n')
    p = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                       timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == '[]'


def test_plan_robust_prints_and_saves_the_mean_over_its_pictures(tmp_path):
    out = tmp_path / 'r.json'
    p = cli('plan', DATA / 'weak20_0.yaml', '--w', '0.6', '--robust', '4',
            '--position-sigma', '5', '--intensity-sigma', '0.1', '--robust-seed', '9',
            '--json', out)
    assert p.returncode == 0, p.stderr
    data = json.loads(out.read_text())
    assert data['robust'] == {'samples': 4, 'position_sigma_m': 5.0, 'intensity_sigma': 0.1,
                              'seed': 9, 'nominal_cost': data['robust']['nominal_cost']}
    sc = load_scenario(DATA / 'weak20_0.yaml')
    path = np.array(data['path'])
    pictures = sample_pictures(sc.threats, 4, Uncertainty(5.0, 0.1), 9, antithetic=True)
    mean = np.mean([path_cost(path, q.positions, q.intensities, 0.6).J for q in pictures])
    assert data['cost']['final']['J'] == pytest.approx(mean, rel=1e-12)
    nominal = path_cost(path, sc.threats.positions, sc.threats.intensities, 0.6)
    assert data['robust']['nominal_cost']['J'] == pytest.approx(nominal.J, rel=1e-12)
    assert 'mean over 4 pictures' in p.stdout and f'J={nominal.J:.3f}' in p.stdout


@pytest.mark.parametrize('args,needle', [
    (['--robust', '0'], '--robust: must be an integer >= 1, got 0'),
    (['--robust', '2', '--position-sigma', '-1'], '--position-sigma: must be a finite'),
    (['--robust', '2', '--intensity-sigma', 'nan'], '--intensity-sigma: must be a finite'),
    (['--robust', '2', '--record', 'x.mcap'], '--robust: a robust plan cannot be recorded'),
])
def test_bad_robust_options_exit_2_with_one_line(tmp_path, args, needle):
    p = cli('plan', DATA / 'weak20_0.yaml', *args, cwd=tmp_path)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], p.stderr
