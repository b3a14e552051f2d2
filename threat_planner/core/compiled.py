"""The compiled kernels made ready: compiled once a machine, loaded once a process.

numba compiles a kernel on its first call with each argument type, and a cached kernel
is loaded on its first call in each process. :func:`compile_all` runs a workload that
calls every kernel with every type the planner passes it (the small plans of
:func:`_workload`; a test checks that the bundled scenarios then compile nothing) and
writes a manifest of those signatures beside the cache. :func:`ensure_compiled` loads
every signature of the manifest (compiling what the cache lacks), so that a node or a
worker process pays for it at start-up and not in its first plan; without a manifest
it runs the workload. ``threat-planner compile``, ``make venv`` and ``setup.py build``
(colcon, pip) call :func:`compile_all`, which builds the ahead-of-time module
(:mod:`.aot_build`) beside the workload, from :mod:`._aot_signatures` (kept only if the
workload's signatures are those; the two took 53 s together on 2 cores, 97 s one after the
other); where that module fits these sources a process uses it instead
(:mod:`._aot`: no numba import, nothing to load), and these functions say so.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import importlib
import json
import os
from pathlib import Path
import pickle
import shutil
import subprocess
import sys
import time

import numpy as np

from threat_planner.core import _aot, _numba_cache

__all__ = ['KERNEL_MODULES', 'KernelReport', 'compile_all', 'ensure_compiled',
           'export_signatures', 'kernel_stats', 'kernels_cached']

#: Every module that defines compiled kernels.
KERNEL_MODULES = ('threat_planner.core.cost.pair_integrals', 'threat_planner.core.cost.kernels',
                  'threat_planner.core.cost.near_kernels', 'threat_planner.core.cost.far_kernels',
                  'threat_planner.core.network.graph_kernels',
                  'threat_planner.core.optimise.lbfgs',
                  'threat_planner.core.optimise.limit_kernels',
                  'threat_planner.core.optimise.lagrangian_kernels',
                  'threat_planner.core.optimise.limits',
                  'threat_planner.core.optimise.chain_kernels')
_MANIFEST = 'signatures.pickle'


@dataclass(frozen=True)
class KernelReport:
    """What making the kernels ready took.

    Attributes:
        seconds: Wall time [s].
        compiled: Kernel signatures compiled (not found in the cache).
        loaded: Kernel signatures loaded from the cache.
        cache: The cache folder.
        aot: Which kernels plans use (the AOT module or the JIT ones, and why), or
            what building the AOT module did.
    """

    seconds: float
    compiled: int
    loaded: int
    cache: str
    aot: str = ''

    def line(self) -> str:
        """One line for a log: compiled or loaded, how many, how long, which kernels."""
        if self.compiled:
            text = (f'compiled {self.compiled} kernel signatures in {self.seconds:.1f} s '
                    f'(once per install of these sources; cache {self.cache})')
        else:
            text = f'loaded {self.loaded} compiled kernels in {self.seconds:.2f} s'
        return f'{text}; {self.aot}' if self.aot else text


def _dispatchers() -> dict[str, object]:
    """Return qualified name -> numba dispatcher of every kernel (modules imported)."""
    if _aot.active():
        # The lazily built JIT kernels, if a large problem built them (numba not imported
        # for this otherwise).
        return dict(_aot._STATE['jit'] or {})
    try:
        from numba.core.dispatcher import Dispatcher
    except ImportError:  # pragma: no cover - numba is in install_requires
        return {}
    out = {}
    for name in KERNEL_MODULES:
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            if isinstance(value, Dispatcher) and value.__module__ == name:
                out[f'{name}.{attr}'] = value
    return out


def kernel_stats() -> tuple[int, int]:
    """Return (loaded from the cache, compiled) signatures over every kernel so far."""
    hits = misses = 0
    for d in _dispatchers().values():
        hits += sum(d.stats.cache_hits.values())
        misses += sum(d.stats.cache_misses.values())
    return hits, misses


def _workload() -> None:
    """Plan the small problems that reach every kernel with every argument type."""
    from threat_planner.core.inputs.config import PlannerConfig
    from threat_planner.core.inputs.settings import NO_LIMITS
    from threat_planner.core.planner import _tiny_plan, plan
    from threat_planner.core.world.airspace import Airspace, make_zone
    from threat_planner.core.world.terrain import Terrain
    from threat_planner.core.world.threats import Box, ThreatField
    for module in ('threat_planner.core.cost.kernels', 'threat_planner.core.network.graph_kernels',
                   'threat_planner.core.optimise.limits'):
        importlib.import_module(module).warm_up()
    _tiny_plan()
    rng = np.random.default_rng(1)
    box = Box.from_corners([0.0, 0.0, 0.0], [100.0, 100.0, 100.0])
    s, t = np.array([2.0, 3.0, 10.0]), np.array([97.0, 96.0, 90.0])
    small = ThreatField.from_arrays(rng.uniform(15.0, 85.0, (20, 3)), rng.uniform(1e3, 1e4, 20))
    crowded = ThreatField.from_arrays(rng.uniform(5.0, 95.0, (300, 3)), np.full(300, 50.0))
    for threats in (small, crowded):
        for extra in ({}, NO_LIMITS):
            first = plan(threats, s, t, box, PlannerConfig(**extra))
        moved = ThreatField.from_arrays(threats.positions + 1e-3, threats.intensities)
        plan(moved, s, t, box, PlannerConfig(**extra), warm_start=first)
    for method in ('paper', 'improved'):
        plan(small, s, t, box, PlannerConfig(method=method))
    # Every plan reports its detection; from COMPILED_THREATS threats on the compiled
    # hazard (detection.kernels, JIT only), which would otherwise compile in a user's plan.
    from threat_planner.core.detection.hazard import path_hazard
    from threat_planner.core.detection.model import DetectionModel
    path_hazard(np.stack([s, t]), crowded.positions, crowded.intensities, DetectionModel())
    heights = 10.0 + 5.0 * np.sin(np.linspace(0.0, 3.0, 11))[None, :] * np.ones((11, 1))
    terrain = Terrain.from_arrays([0.0, 0.0], 10.0, heights, clearance=2.0, masking=True)
    air = Airspace((make_zone('sphere', 'no_fly_zones[0]', center=[50.0, 50.0, 50.0],
                              radius=8.0),), terrain)
    plan(small, np.array([2.0, 3.0, 40.0]), t, box, PlannerConfig(), airspace=air)


def _manifest_path():
    return _numba_cache.cache_dir() / _MANIFEST


def _write_manifest() -> None:
    sigs = {name: list(d.signatures) for name, d in _dispatchers().items() if d.signatures}
    try:
        path = _manifest_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix('.tmp')
        tmp.write_bytes(pickle.dumps(sigs))
        tmp.replace(path)
    except OSError:
        pass  # an unwritable cache: the next process runs the workload again


def _read_manifest() -> dict | None:
    try:
        sigs = pickle.loads(_manifest_path().read_bytes())
    except Exception:  # noqa: BLE001 - missing or damaged: run the workload instead
        return None
    return sigs if isinstance(sigs, dict) else None


def _report(t0: float, before: tuple[int, int]) -> KernelReport:
    hits, misses = kernel_stats()
    return KernelReport(time.perf_counter() - t0, misses - before[1], hits - before[0],
                        str(_numba_cache.cache_dir()))


def kernels_cached() -> bool:
    """Whether :func:`ensure_compiled` compiles nothing: AOT kernels, or a JIT manifest."""
    # The manifest holds numba types: reading it imports numba (0.26 s in a node's start-up)
    # on the AOT path, which never needs it.
    return _aot.active() or _read_manifest() is not None


def _child_env() -> dict:
    """Return the environment of a JIT-path child, with this process's copy of the sources."""
    package = str(Path(__file__).resolve().parents[2])
    return dict(os.environ, THREAT_PLANNER_AOT='0', PYTHONPATH=os.pathsep.join(
        [package] + [p for p in [os.environ.get('PYTHONPATH')] if p]))


def _child(code: str, timeout: float) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter on the JIT path, with this process's path."""
    return subprocess.run([sys.executable, '-c', code], env=_child_env(), capture_output=True,
                          text=True, timeout=timeout)


def export_signatures() -> dict[str, tuple[str, tuple[str, ...]]]:
    """Each export's (return type, argument types) as the manifest and the JIT cache say."""
    sigs = _read_manifest()
    if not sigs:
        raise RuntimeError('no signature manifest: the JIT workload did not run')
    disp = _dispatchers()
    out = {}
    for qual in _aot.quals():
        if len(sigs.get(qual, ())) != 1:
            raise RuntimeError(f'{qual}: {len(sigs.get(qual, ()))} signatures, 1 expected')
        disp[qual].compile(sigs[qual][0])
        full = disp[qual].overloads[sigs[qual][0]].signature
        out[qual] = (str(full.return_type), tuple(str(t) for t in full.args))
    return out


def _start_early_build() -> tuple[subprocess.Popen, Path] | None:
    """Start building the AOT module from the committed signatures, beside the workload.

    The build (~45 s) needs only the exports' signatures, which :mod:`._aot_signatures`
    holds; the JIT workload (~45 s) runs meanwhile on the other core. It builds into a
    staging folder that :func:`build_aot` keeps only if the workload's signatures are those.
    """
    if _aot.load()[0] is not None:
        return None
    staging = _aot.aot_dir().parent / f'.staged-{os.getpid()}'
    code = ('import sys; from threat_planner.core.aot_build import main; '
            f'sys.exit(main([{str(staging)!r}, "--committed"]))')
    try:
        return subprocess.Popen([sys.executable, '-c', code], env=_child_env(), text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL), staging
    except OSError:
        return None


def _finish_early_build(early: tuple[subprocess.Popen, Path]) -> str | None:
    """Put the early build in place; its line, or None to build from the manifest."""
    proc, staging = early
    try:
        out, _ = proc.communicate(timeout=1800)
        if proc.returncode != 0 or not (staging / _aot.STAMP).is_file():
            return None
        from threat_planner.core._aot_signatures import SIGNATURES
        if export_signatures() != SIGNATURES:
            return None  # the sources changed the types: the module must not be used
        _aot.move_into_place(staging, _aot.aot_dir())
        return (out.strip().splitlines()[-1].replace(str(staging), str(_aot.aot_dir()))
                + ', beside the JIT workload')
    except Exception:  # noqa: BLE001 - a failed early build: the build from the manifest
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        return None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def build_aot(early: tuple[subprocess.Popen, Path] | None = None) -> str:
    """Build the AOT module of these sources unless it is there; return one line.

    ``early``: the build :func:`_start_early_build` began, kept if it fits the workload.
    Any failure (no C compiler, no Python headers, numba.pycc missing, an error) is that
    line; plans then use the JIT kernels.
    """
    line = None if early is None else _finish_early_build(early)
    if line is not None:
        return line
    module, _ = _aot.load()
    if module is not None:
        return f'AOT kernels up to date ({_aot.aot_dir()})'
    try:
        done = _child('import sys; from threat_planner.core.aot_build import main; '
                      'sys.exit(main())', timeout=1800)
    except (OSError, subprocess.SubprocessError) as exc:
        return f'AOT kernels not built ({exc}); plans use the JIT kernels'
    lines = (done.stdout.strip() or done.stderr.strip() or 'no output').splitlines()
    if done.returncode == 0:
        return lines[-1]
    return f'AOT kernels not built ({lines[-1][:200]}); plans use the JIT kernels'


def compile_all(aot: bool | None = None) -> KernelReport:
    """Compile (or load) every kernel through the workload, write the manifest, build AOT.

    Parameters
    ----------
    aot : bool, optional
        Build the ahead-of-time module, beside the workload (~45 s once per install of these
        sources; skipped where it is there already). Default: yes, unless
        ``THREAT_PLANNER_AOT_BUILD=0`` (the tests that compile into empty caches).

    """
    if aot is None:
        aot = os.environ.get('THREAT_PLANNER_AOT_BUILD', '').strip() != '0'
    if _aot.active():
        # This process's kernels are the AOT ones: the workload fills the JIT cache in a
        # JIT process (the lazily built parallel kernels and THREAT_PLANNER_AOT=0 use it).
        done = _child('import json; from threat_planner.core.compiled import compile_all; '
                      'r = compile_all(aot=False); '
                      'print(json.dumps([r.seconds, r.compiled, r.loaded, r.cache]))', 1800)
        if done.returncode:
            raise RuntimeError(done.stderr.strip()[-2000:])
        report = KernelReport(*json.loads(done.stdout.strip().splitlines()[-1]))
    else:
        early = _start_early_build() if aot else None
        t0, before = time.perf_counter(), kernel_stats()
        try:
            _workload()
            _write_manifest()
        except BaseException:
            if early is not None:
                early[0].kill()
                early[0].communicate()
                shutil.rmtree(early[1], ignore_errors=True)
            raise
        report = _report(t0, before)
        if early is not None:
            return replace(report, aot=build_aot(early))
    if not aot:
        return report
    return replace(report, aot=build_aot())


def ensure_compiled() -> KernelReport:
    """Load every kernel signature of the manifest (compile any the cache lacks).

    With the AOT kernels there is nothing to load: the report says so (no numba import).
    """
    if _aot.active():
        return KernelReport(0.0, 0, _aot.install(), str(_aot.aot_dir()), _aot.status())
    t0, before = time.perf_counter(), kernel_stats()
    sigs = _read_manifest()
    dispatchers = _dispatchers()
    if sigs is None or not set(sigs) <= set(dispatchers):
        return replace(compile_all(aot=False), aot=_aot.status())
    for name, signatures in sigs.items():
        for sig in signatures:
            try:
                dispatchers[name].compile(sig)
            except Exception:  # noqa: BLE001 - a signature that no longer fits: it
                return compile_all(aot=False)  # compiles on first use; new manifest
    return replace(_report(t0, before), aot=_aot.status())
