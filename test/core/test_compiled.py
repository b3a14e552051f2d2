"""The compiled kernels: one cache for every install of the same sources, never a crash.

Each claim runs in a fresh interpreter, as a user's process would meet the cache.
"""

import json
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

from threat_planner.core import _numba_cache
from threat_planner.core.compiled import ensure_compiled

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / 'test' / 'data'


@pytest.fixture(scope='module', autouse=True)
def warm_cache():
    """The user cache holds every kernel (``make venv`` compiled them; this loads them)."""
    ensure_compiled()


def run(code: str, env: dict | None = None, cwd: Path = ROOT) -> dict:
    """Run `code` in a fresh JIT-path interpreter; return the JSON it prints last.

    These are the JIT cache's claims: THREAT_PLANNER_AOT=0 (test_aot.py has the AOT's).
    """
    full = dict(os.environ, THREAT_PLANNER_AOT='0', **(env or {}))
    p = subprocess.run([sys.executable, '-c', code], cwd=cwd, env=full, capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


REPORT = ('import json, threat_planner.core.compiled as c\n'
          'r = c.ensure_compiled()\n'
          'print(json.dumps({"file": c.__file__, "compiled": r.compiled, "loaded": r.loaded}))\n')


def test_a_copy_of_the_package_elsewhere_loads_the_same_cache(tmp_path):
    """Another install path (colcon's, pip's, a new clone) compiles nothing."""
    shutil.copytree(ROOT / 'threat_planner', tmp_path / 'elsewhere' / 'threat_planner',
                    ignore=shutil.ignore_patterns('__pycache__'))
    out = run(REPORT, {'PYTHONPATH': str(tmp_path / 'elsewhere')}, cwd=tmp_path)
    assert out['file'].startswith(str(tmp_path))
    assert out['compiled'] == 0 and out['loaded'] >= 15


def test_after_the_workload_no_bundled_plan_compiles():
    """The manifest's signatures are every one the planner uses: methods, limits, airspace."""
    code = (
        'import glob, json\n'
        'from threat_planner.core import load_scenario, plan, PlannerConfig\n'
        'from threat_planner.core.compiled import ensure_compiled, kernel_stats\n'
        'from threat_planner.core.inputs.settings import NO_LIMITS\n'
        'ensure_compiled()\n'
        'before = kernel_stats()\n'
        f'for f in sorted(glob.glob({str(DATA / "*.yaml")!r})):\n'
        # air_geofence_0's one zone is a prism, as air_mixed_0's (3.4 s of plans saved).
        '    if f.endswith("air_geofence_0.yaml"):\n'
        '        continue\n'
        '    sc = load_scenario(f)\n'
        '    big = len(sc.threats) >= 100\n'
        '    runs = ([] if big else [{}]) + [dict(NO_LIMITS)]\n'
        '    if f.endswith("uniform20_0.yaml"):\n'
        '        runs += [{"method": "paper"}, {"method": "improved"}]\n'
        '    for extra in runs:\n'
        '        plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5, **extra),\n'
        '             airspace=sc.airspace)\n'
        'after = kernel_stats()\n'
        'print(json.dumps({"compiled": after[1] - before[1], "loaded": after[0] - before[0]}))\n')
    out = run(code)
    assert out['compiled'] == 0


def _cache_copy(tmp_path: Path) -> Path:
    base = tmp_path / 'cache'
    shutil.copytree(_numba_cache.cache_dir(), base / _numba_cache.sources_digest())
    return base


GRAPH = ('import json\n'
         'import numpy as np\n'
         'from threat_planner.core.compiled import kernel_stats\n'
         'from threat_planner.core.network.graph_kernels import Graph\n'
         'd = Graph(3, np.array([[0, 1], [1, 2]])).shortest(np.array([1.0, 2.0]), 0)\n'
         'print(json.dumps({"d": [float(x) for x in np.ravel(d[0] if isinstance(d, tuple) '
         'else d)][:3], "stats": kernel_stats()}))\n')


def test_a_corrupt_cache_file_compiles_again_and_plans(tmp_path):
    base = _cache_copy(tmp_path)
    damaged = list((base / _numba_cache.sources_digest() / 'network').glob('*.nb[ic]'))
    assert damaged
    for f in damaged:
        f.write_bytes(b'\x80\x04not a pickle at all' * 7)
    out = run(GRAPH, {'THREAT_PLANNER_CACHE_DIR': str(base)})
    assert out['stats'][1] >= 1          # compiled again, instead of raising
    healthy = run(GRAPH)
    assert out['d'] == healthy['d']
    # and a plan on that cache is the plan on a healthy one (damaged: the search's kernel)
    plan = ('import json\nfrom threat_planner.core import load_scenario, plan\n'
            f'sc = load_scenario({str(DATA / "weak20_0.yaml")!r})\n'
            'r = plan(sc.threats, sc.start, sc.goal, sc.box)\n'
            'print(json.dumps({"J": r.cost.J}))\n')
    assert run(plan, {'THREAT_PLANNER_CACHE_DIR': str(base)})['J'] == run(plan)['J']


def test_an_unwritable_cache_folder_falls_back_to_the_temporary_one(tmp_path):
    """Root can write anywhere, so the folder is made impossible: a file stands in its way."""
    blocker = tmp_path / 'not_a_folder'
    blocker.write_text('a file, so nothing can be made below it')
    tmp = tmp_path / 'tmp'
    tmp.mkdir()
    out = run(GRAPH, {'THREAT_PLANNER_CACHE_DIR': str(blocker / 'cache'), 'TMPDIR': str(tmp)})
    assert out['d'] == run(GRAPH)['d']
    assert list(tmp.glob(f'threat_planner-numba-*/{_numba_cache.sources_digest()}/network/*.nbi'))


def test_compile_check_loads_what_the_cache_holds():
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'compile', '--check'],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith('loaded ') and 'compiled kernels in' in p.stdout


@pytest.mark.parametrize('given, spins', [
    ({}, str(_numba_cache.SPIN_COUNT)), ({'OMP_WAIT_POLICY': 'ACTIVE'}, '30000000000'),
    ({'GOMP_SPINCOUNT': '77'}, '77')])
def test_the_parallel_kernels_threads_sleep_soon_after_a_loop_unless_told(given, spins):
    """libgomp's own report (OMP_DISPLAY_ENV) of a plan on the parallel kernels.

    Unset, libgomp spins 300,000 times before it sleeps; the package makes that
    SPIN_COUNT, and a user's setting stands.
    """
    env = {k: v for k, v in os.environ.items()
           if k not in ('OMP_WAIT_POLICY', 'GOMP_SPINCOUNT')}
    env.update(given, OMP_DISPLAY_ENV='VERBOSE')
    code = ('import numpy as np\n'
            'from threat_planner import Box, plan, PlannerConfig, ThreatField\n'
            'rng = np.random.default_rng(0)\n'
            'threats = ThreatField.from_arrays(rng.uniform(5, 95, (400, 3)), '
            'np.full(400, 1e3))\n'
            'plan(threats, [0, 0, 50], [100, 100, 50], '
            'Box.from_corners([0, 0, 0], [100, 100, 100]), PlannerConfig())\n'
            'import numba\n'
            'print(numba.threading_layer())\n')
    done = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                          text=True, check=True)
    if done.stdout.strip().splitlines()[-1] != 'omp':
        pytest.skip('numba runs another threading layer here')
    assert f"GOMP_SPINCOUNT = '{spins}'" in done.stderr, done.stderr[-2000:]
