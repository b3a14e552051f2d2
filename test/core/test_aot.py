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
            'from threat_planner.core import _aot, load_scenario, plan, PlannerConfig\n'
            f'sc = load_scenario({str(ROOT / "test" / "data" / "weak20_0.yaml")!r})\n'
            'r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5),\n'
            '         airspace=sc.airspace)\n'
            'print(json.dumps({"J": repr(r.cost.J), "path": r.path.tolist(), "status": '
            '_aot.status(), "active": _aot.active(), "numba": "numba" in sys.modules}))\n')
ONE_KEY = 'weak20_0.yaml w0.5 on'
COMPILE = ['-m', 'threat_planner.cli', 'compile']


def _env(env: dict | None) -> dict:
    full = {k: v for k, v in os.environ.items()
            if k not in ('THREAT_PLANNER_AOT', 'THREAT_PLANNER_AOT_BUILD')}
    full.update(env or {})
    return full


def start(args: list, env: dict | None = None) -> subprocess.Popen:
    """Start python `args` in a fresh interpreter (they run side by side: ~2x less wall)."""
    return subprocess.Popen([sys.executable, *args], cwd=ROOT, env=_env(env), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def finish(proc: subprocess.Popen, timeout: float = 900) -> str:
    """Wait for `proc`; return its output, it having succeeded."""
    out, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, err[-3000:]
    return out


def last_json(out: str) -> dict:
    """Return the JSON of the last line."""
    return json.loads(out.strip().splitlines()[-1])


def _cache_copy(tmp: Path) -> Path:
    base = tmp / 'cache'
    shutil.copytree(_numba_cache.cache_dir(), base / _numba_cache.sources_digest())
    return base


def _aot_copy(base: Path) -> Path:
    return base / _numba_cache.sources_digest() / 'aot' / _aot.tag()


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """Every subprocess of this module, started at once; name -> Popen (and caches)."""
    module, why = _aot.load()
    if module is None:
        pytest.fail(f'run threat-planner compile first: {why}')
    caches = {}
    for damage in ('stale', 'corrupt', 'build'):
        caches[damage] = base = _cache_copy(tmp_path_factory.mktemp(damage))
        folder = _aot_copy(base)
        if damage == 'stale':
            stamp = json.loads((folder / _aot.STAMP).read_text())
            stamp['digest'] = '0' * 16
            (folder / _aot.STAMP).write_text(json.dumps(stamp))
        elif damage == 'corrupt':
            _aot.module_path(folder).write_bytes(b'\x7fELF not a shared object' * 40)
        else:
            shutil.rmtree(folder.parent)
    procs = {'build': start(COMPILE, {'THREAT_PLANNER_CACHE_DIR': str(caches['build'])}),
             'aot': start([str(PLANS), '--check']),
             'jit': start([str(PLANS)], {'THREAT_PLANNER_AOT': '0'})}
    for damage in ('stale', 'corrupt'):
        procs[damage] = start(['-c', ONE_PLAN],
                              {'THREAT_PLANNER_CACHE_DIR': str(caches[damage])})
    yield procs, caches
    for proc in procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


@pytest.fixture(scope='module')
def both(runs):
    """The representative set planned on the AOT path (types checked) and the JIT path."""
    procs, _ = runs
    return last_json(finish(procs['aot'])), last_json(finish(procs['jit']))


def test_aot_and_jit_plans_are_equal_bit_for_bit(both):
    aot, jit = both
    assert aot['active'] and aot['status'].startswith('AOT kernels loaded'), aot['status']
    assert not jit['active'] and 'THREAT_PLANNER_AOT=0' in jit['status']
    assert len(aot['plans']) >= 58 and aot['plans'].keys() == jit['plans'].keys()
    differ = [k for k in aot['plans'] if aot['plans'][k] != jit['plans'][k]]
    assert not differ, differ


def test_the_aot_path_imports_no_numba_for_small_problems(both):
    aot, jit = both
    assert aot['numba_small'] is False      # 64 small plans, then the 300-threat one
    assert jit['numba_small'] is True


def test_every_call_passes_exactly_the_exported_types(both):
    """A float32 or non-contiguous argument is garbage or a crash in an AOT kernel."""
    aot, _ = both
    # every export wrapped; 15 of the 18 called here (layouts seen, one example each)
    assert aot['shims'] >= len(_aot.quals()) and aot['checked'] >= 12
    assert aot['bad'] == []


@pytest.mark.parametrize('damage', ['stale', 'corrupt'])
def test_a_stale_or_corrupt_module_falls_back_to_jit(runs, both, damage):
    out = last_json(finish(runs[0][damage]))
    assert not out['active'] and out['numba']
    assert ('stale' if damage == 'stale' else 'did not import') in out['status'], out['status']
    assert [out['J'], out['path']] == both[1]['plans'][ONE_KEY]


def test_a_module_built_for_another_cpu_is_not_loaded(monkeypatch):
    """The module is built for the host CPU, so its folder and stamp name that CPU."""
    here = _aot.aot_dir()
    assert _aot.tag().endswith('-cpu' + _aot.cpu_id()) and len(_aot.cpu_id()) == 8
    assert _aot.load(here)[0] is not None
    monkeypatch.setattr(_aot, 'cpu_id', lambda: 'deadbeef')
    assert _aot.aot_dir() != here and _aot.load()[1].startswith('no AOT module')
    module, why = _aot.load(here)          # copied into this CPU's folder by hand
    assert module is None and why.startswith('stale AOT module') and 'cpu' in why, why


def test_compile_builds_the_module_once_and_a_fresh_process_uses_it(runs, both):
    """The one AOT build of the suite (~60 s): into a copy of the cache without it."""
    procs, caches = runs
    out = finish(procs['build'], timeout=1500)
    assert len(out.strip().splitlines()) == 1, out
    # from the committed signatures, beside the workload (test_aot_signatures.py)
    assert '; built the AOT kernels' in out and out.strip().endswith('beside the JIT workload')
    env = {'THREAT_PLANNER_CACHE_DIR': str(caches['build'])}
    assert _aot.module_path(_aot_copy(caches['build'])).is_file()
    plan = last_json(finish(start(['-c', ONE_PLAN], env)))
    assert plan['active'] and not plan['numba']
    assert [plan['J'], plan['path']] == both[1]['plans'][ONE_KEY]
    # a second compile finds it there and builds nothing
    assert '; AOT kernels up to date' in finish(start(COMPILE, env))


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


def test_compile_no_aot_skips_the_build():
    """What the tests that compile into empty caches use: `--no-aot`."""
    out = finish(start([*COMPILE, '--no-aot']))
    assert 'AOT' not in out and out.startswith(('loaded ', 'compiled ')), out


def test_the_kernel_helpers_import_no_numba_on_the_aot_path():
    """ensure_compiled, kernels_cached (the node's start), kernel_stats, the batch
    worker's set-up: all without numba (reading the JIT manifest imported it: 0.26 s)."""
    assert _aot.load()[0] is not None, 'run threat-planner compile first'
    code = ('import json, sys\n'
            'from threat_planner.core.compiled import ensure_compiled, kernel_stats, '
            'kernels_cached\n'
            'from threat_planner.batch import local, worker\n'
            'assert kernels_cached()\n'
            'r = ensure_compiled()\n'
            'worker.initialise()\n'
            'print(json.dumps({"line": r.line(), "stats": kernel_stats(), "numba": "numba" in '
            'sys.modules, "start": local.start_method()}))\n')
    out = last_json(finish(start(['-c', code])))
    assert out['numba'] is False and out['stats'] == [0, 0] and out['start'] == 'fork'
    assert out['line'].startswith(f'loaded {len(_aot.quals())} compiled kernels') and \
        '; AOT kernels loaded from' in out['line'], out['line']


def test_the_aot_routing_threshold_is_the_jit_path_s_own():
    """_aot sits below cost in the layers, so it keeps a copy of the JIT path's threshold
    for its parallel kernels: the two must not drift apart."""
    from threat_planner.core.cost.kernels import PARALLEL_PAIRS
    assert _aot.PARALLEL_PAIRS == PARALLEL_PAIRS
