"""The ahead-of-time kernels: the JIT path's plans, exact argument types, safe fallbacks.

Each claim runs in fresh interpreters, as a user's process meets the cache: the AOT path
(THREAT_PLANNER_AOT unset, the module ``threat-planner compile`` built) against the JIT
path (THREAT_PLANNER_AOT=0). One test builds the module (into a copy of this machine's
cache without it); every other compile in the suite skips that build.
"""

import json
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

from threat_planner.core import _aot, _numba_cache, compiled

ROOT = Path(__file__).resolve().parents[2]
PLANS = Path(__file__).with_name('aot_plans.py')
ONE_PLAN = ('import json, sys\n'
            'from threat_planner.core import _aot, load_scenario, plan\n'
            f'sc = load_scenario({str(ROOT / "test" / "data" / "weak20_0.yaml")!r})\n'
            'r = plan(sc.threats, sc.start, sc.goal, sc.box)\n'
            'print(json.dumps({"J": repr(r.cost.J), "path": r.path.tolist(), "status": '
            '_aot.status(), "active": _aot.active(), "numba": "numba" in sys.modules}))\n')


def run(args: list, env: dict | None = None, timeout: float = 600) -> dict:
    """Run python `args` in a fresh interpreter; return the JSON it prints last."""
    full = dict(os.environ, **(env or {}))
    full.pop('THREAT_PLANNER_AOT', None)
    full.update(env or {})
    p = subprocess.run([sys.executable, *args], cwd=ROOT, env=full, capture_output=True,
                       text=True, timeout=timeout)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.fixture(scope='module')
def aot_module():
    """This machine's cache has the AOT module (``threat-planner compile`` built it)."""
    module, why = _aot.load()
    if module is None:
        pytest.fail(f'run threat-planner compile first: {why}')
    return _aot.aot_dir()


@pytest.fixture(scope='module')
def both(aot_module):
    """The representative set planned on the AOT path (types checked) and the JIT path."""
    return run([str(PLANS), '--check']), run([str(PLANS)], {'THREAT_PLANNER_AOT': '0'})


def test_aot_and_jit_plans_are_equal_bit_for_bit(both):
    aot, jit = both
    assert aot['active'] and aot['status'].startswith('AOT kernels loaded'), aot['status']
    assert not jit['active'] and 'THREAT_PLANNER_AOT=0' in jit['status']
    assert len(aot['plans']) >= 80 and aot['plans'].keys() == jit['plans'].keys()
    differ = [k for k in aot['plans'] if aot['plans'][k] != jit['plans'][k]]
    assert not differ, differ


def test_the_aot_path_imports_no_numba_for_small_problems(both):
    aot, jit = both
    assert aot['numba_small'] is False      # 78 small plans, then the 300-threat one
    assert jit['numba_small'] is True


def test_every_call_passes_exactly_the_exported_types(both):
    """A float32 or non-contiguous argument is garbage or a crash in an AOT kernel."""
    aot, _ = both
    assert aot['shims'] >= len(_aot.quals()) and aot['checked'] >= len(_aot.quals())
    assert aot['bad'] == []


def _cache_copy(tmp_path: Path) -> Path:
    base = tmp_path / 'cache'
    shutil.copytree(_numba_cache.cache_dir(), base / _numba_cache.sources_digest())
    return base


def _aot_copy(base: Path) -> Path:
    return base / _numba_cache.sources_digest() / 'aot' / _aot.tag()


@pytest.mark.parametrize('damage', ['stale', 'corrupt'])
def test_a_stale_or_corrupt_module_falls_back_to_jit(aot_module, tmp_path, damage):
    base = _cache_copy(tmp_path)
    folder = _aot_copy(base)
    if damage == 'stale':
        stamp = json.loads((folder / _aot.STAMP).read_text())
        stamp['digest'] = '0' * 16
        (folder / _aot.STAMP).write_text(json.dumps(stamp))
    else:
        _aot.module_path(folder).write_bytes(b'\x7fELF not a shared object' * 40)
    out = run(['-c', ONE_PLAN], {'THREAT_PLANNER_CACHE_DIR': str(base)})
    assert not out['active'] and out['numba']
    assert ('stale' if damage == 'stale' else 'did not import') in out['status'], out['status']
    healthy = run(['-c', ONE_PLAN])
    assert healthy['active'] and not healthy['numba']
    assert (out['J'], out['path']) == (healthy['J'], healthy['path'])


def test_compile_builds_the_module_once_and_a_fresh_process_uses_it(aot_module, tmp_path):
    """The one AOT build of the suite (~60 s): into a copy of the cache without it."""
    base = _cache_copy(tmp_path)
    shutil.rmtree(base / _numba_cache.sources_digest() / 'aot')
    env = dict(os.environ, THREAT_PLANNER_CACHE_DIR=str(base))
    env.pop('THREAT_PLANNER_AOT', None)
    env.pop('THREAT_PLANNER_AOT_BUILD', None)
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'compile'], cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=1200)
    assert p.returncode == 0, p.stderr[-3000:]
    assert len(p.stdout.strip().splitlines()) == 1, p.stdout
    assert '; built the AOT kernels' in p.stdout, p.stdout
    assert _aot.module_path(_aot_copy(base)).is_file()
    out = run(['-c', ONE_PLAN], {'THREAT_PLANNER_CACHE_DIR': str(base)})
    assert out['active'] and not out['numba']
    assert out['J'] == run(['-c', ONE_PLAN], {'THREAT_PLANNER_AOT': '0'})['J']
    # a second compile finds it there and builds nothing
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'compile'], cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0 and '; AOT kernels up to date' in p.stdout, p.stdout


def test_a_build_that_cannot_run_is_one_line_and_plans_stay_jit(tmp_path, monkeypatch):
    monkeypatch.setenv('THREAT_PLANNER_CACHE_DIR', str(tmp_path / 'empty'))
    # no signature manifest in that cache: the build says why, in one line
    line = compiled.build_aot()
    assert line.startswith('AOT kernels not built (RuntimeError: no signature manifest')
    assert line.endswith('plans use the JIT kernels') and '\n' not in line

    def no_python(*args, **kwargs):
        raise FileNotFoundError('no such interpreter')
    monkeypatch.setattr(compiled, '_child', no_python)
    assert compiled.build_aot() == ('AOT kernels not built (no such interpreter); plans use '
                                    'the JIT kernels')


def test_compile_no_aot_skips_the_build(tmp_path):
    """What the tests that compile into empty caches use: `--no-aot`."""
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'compile', '--no-aot'],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    assert 'AOT' not in p.stdout and p.stdout.startswith(('loaded ', 'compiled ')), p.stdout
