"""The kernels from the ahead-of-time module (numba.pycc), where one fits these sources.

``threat-planner compile`` builds ``_aot_kernels`` (:mod:`.aot_build`) into the cache
folder of these sources (:func:`._numba_cache.cache_dir`), under the Python ABI and numpy
major version and CPU it was built for (:func:`aot_dir`). When a process starts and that module
imports, with its stamp naming these sources, the kernel modules are imported without
numba (their ``njit`` is :func:`stub_njit`: it records the function and returns it) and
:func:`install` puts the AOT function in place of every Python-called kernel. A fresh
process's first plan then takes 26 ms instead of 293 ms (uniform20_0; numba's import and
the cached kernels' loads are what it saves). Otherwise, or with ``THREAT_PLANNER_AOT=0``,
the JIT path runs exactly as before.

One source of truth: the exported functions are the same Python functions, compiled by
pycc instead of numba's JIT. pycc cannot launch numba's threading layer, so they are
serial; the problems large enough for the parallel kernels go to JIT kernels built
lazily from the same functions (:func:`jit`, numba imported then; :func:`_route`).
The exported functions check no argument type (a float32 or non-contiguous array is
read as float64 C-contiguous memory): every Python call site passes the exported types,
which ``test/core/test_aot.py`` checks over the bundled scenarios (``aot_plans.py``).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import json
import os
from pathlib import Path
import platform
import shutil
import sys
import sysconfig
import threading
import types

__all__ = ['ENTRY', 'active', 'aot_dir', 'install', 'jit', 'module', 'move_into_place', 'status',
           'stub_njit']

#: Kernels called from Python (not only from other kernels), by module: the exports.
ENTRY = {
    'threat_planner.core.cost.kernels': ('_kernel', '_segment_costs', '_segment_costs_parallel',
                                         '_path_threat_cost'),
    'threat_planner.core.cost.near_kernels': ('_bin', '_near_costs'),
    'threat_planner.core.cost.far_kernels': ('_far_pairs',),
    'threat_planner.core.network.graph_kernels': ('_dijkstra', 'incentre_kernel'),
    'threat_planner.core.optimise.lbfgs': ('_objective', 'objective_scale', '_minimise'),
    'threat_planner.core.optimise.limit_kernels': ('_measure', '_values', '_penalty',
                                                   '_jacobian'),
    'threat_planner.core.optimise.lagrangian_kernels': ('_rounds',),
    'threat_planner.core.optimise.chain_kernels': ('_integrate', '_resample'),
}
MODULE_NAME = '_aot_kernels'
STAMP = 'stamp.json'

#: qualified name -> (python function, njit options), filled by :func:`stub_njit`.
REGISTRY: dict[str, tuple] = {}
_STATE: dict = {'module': None, 'checked': False, 'status': 'not checked', 'jit': None,
                'snapshots': {}, 'installed': 0}
_LOCK = threading.Lock()


def symbol(qual: str) -> str:
    """Return the exported name of kernel ``module.function`` (``kernels__segment_costs``)."""
    mod, name = qual.rsplit('.', 1)
    return mod.rsplit('.', 1)[1] + '__' + name.lstrip('_')


def tag() -> str:
    """Return what an AOT module is built for: Python ABI, numpy major version and CPU."""
    import numpy
    abi = sysconfig.get_config_var('SOABI') or sys.implementation.cache_tag
    return f'{abi}-numpy{numpy.__version__.split(".")[0]}-cpu{cpu_id()}'


@functools.lru_cache(maxsize=None)
def cpu_id() -> str:
    """Return 8 hex digits naming this CPU's model and instruction set.

    The module is built for the host CPU (``target_cpu='host'``, as numba's JIT does; the
    generic target made warm plans ~10 % slower), so a cache folder shared by machines
    keeps one module per CPU, and a module built elsewhere is never loaded here. Linux
    reads ``/proc/cpuinfo`` (llvmlite would say it too, but costs 50 ms to import).
    """
    text = ''
    try:
        with open('/proc/cpuinfo', encoding='utf-8', errors='replace') as f:
            block = f.read().split('\n\n', 1)[0]
        keys = ('vendor_id', 'model name', 'flags', 'Features', 'CPU part')
        lines = [line for line in block.splitlines() if line.split(':', 1)[0].strip() in keys]
        text = '\n'.join(lines)
    except OSError:
        pass
    text = text or f'{platform.machine()} {platform.processor()}'
    return hashlib.sha1(text.encode()).hexdigest()[:8]


def aot_dir() -> Path:
    """Return the folder of the AOT module of these sources, this Python and this numpy."""
    from threat_planner.core import _numba_cache
    return _numba_cache.cache_dir() / 'aot' / tag()


def module_path(folder: Path | None = None) -> Path:
    """Return the path of the extension module in `folder` (default :func:`aot_dir`)."""
    return (folder or aot_dir()) / (MODULE_NAME + sysconfig.get_config_var('EXT_SUFFIX'))


def wanted() -> bool:
    """Whether the AOT kernels may be used (``THREAT_PLANNER_AOT=0`` forces the JIT path)."""
    return os.environ.get('THREAT_PLANNER_AOT', '').strip() not in ('0', 'false', 'no')


def load(folder: Path | None = None):
    """Import the AOT module of `folder`; return (module or None, why not / what)."""
    from threat_planner.core import _numba_cache
    folder = folder or aot_dir()
    path = module_path(folder)
    try:
        stamp = json.loads((folder / STAMP).read_text())
    except (OSError, ValueError):
        return None, f'no AOT module for these sources ({folder})'
    if stamp.get('digest') != _numba_cache.sources_digest() or stamp.get('tag') != tag():
        return None, f'stale AOT module (built for {stamp.get("digest")}, {stamp.get("tag")})'
    try:
        spec = importlib.util.spec_from_file_location(
            f'threat_planner.core.{MODULE_NAME}', path)
        m = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(m)
    except Exception as exc:  # noqa: BLE001 - a damaged module must never stop a plan
        return None, f'AOT module did not import ({type(exc).__name__}: {exc})'[:300]
    missing = [q for q in quals() if not hasattr(m, symbol(q))]
    if missing:
        return None, f'AOT module lacks {symbol(missing[0])}'
    return m, f'AOT kernels loaded from {path}'


def move_into_place(folder: Path, final: Path) -> None:
    """Make `folder` the module folder `final` at once (a half-built one is never found)."""
    old = final.with_name(final.name + f'.old-{os.getpid()}')
    if final.exists():
        final.rename(old)
    folder.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def quals() -> list[str]:
    """Return the qualified names of the exported kernels."""
    return [f'{mod}.{name}' for mod, names in ENTRY.items() for name in names]


def module():
    """Return the AOT extension module, or None (disabled, missing, unloadable or stale)."""
    if not _STATE['checked']:
        with _LOCK:
            if not _STATE['checked']:
                if wanted():
                    _STATE['module'], _STATE['status'] = load()
                else:
                    _STATE['status'] = 'JIT kernels: THREAT_PLANNER_AOT=0'
                _STATE['checked'] = True
    return _STATE['module']


def active() -> bool:
    """Whether this process plans with the AOT kernels (decided at the first import)."""
    return module() is not None and bool(REGISTRY)


def status() -> str:
    """Return one line saying which kernels this process uses and why."""
    module()
    return _STATE['status']


def stub_njit(*args, **kwargs):
    """Return njit of the AOT path: record the function and its options, return it as is."""
    def record(fn):
        REGISTRY[f'{fn.__module__}.{fn.__name__}'] = (fn, kwargs)
        return fn
    if args and callable(args[0]):
        return record(args[0])
    return record


def install() -> int:
    """Put each exported kernel in place of its Python function in every loaded module."""
    m = module()
    if m is None or _STATE['installed']:
        return _STATE['installed']
    from threat_planner.core import _numba_cache
    names = ['threat_planner.core.' + s[:-3].replace('/', '.') for s in _numba_cache.SOURCES
             if s not in _numba_cache.JIT_ONLY]
    for name in names:
        importlib.import_module(name)
    for name in names:
        _STATE['snapshots'][name] = dict(vars(sys.modules[name]))
    swap = {id(REGISTRY[q][0]): _route(q, getattr(m, symbol(q))) for q in quals()}
    for modname, mod in list(sys.modules.items()):
        if modname.startswith('threat_planner') and mod is not None:
            ns = vars(mod)
            for attr, value in list(ns.items()):
                if callable(value) and id(value) in swap:
                    ns[attr] = swap[id(value)]
    _STATE['installed'] = len(swap)
    return len(swap)


# -- the parallel paths: JIT kernels, built lazily, for large problems only -------------

def jit() -> dict:
    """Return qualified name -> numba dispatcher, built from the same Python functions.

    Each function is made again over a copy of its module's namespace (taken before the
    AOT swap) in which the kernels are dispatchers, so callees compile as numba expects.
    Same code, same files: numba's cache entries that ``threat-planner compile`` wrote
    are the ones loaded.
    """
    with _LOCK:
        if _STATE['jit'] is None:
            from threat_planner.core import _numba_cache
            _numba_cache.import_numba()
            _numba_cache.configure()
            import numba
            spaces = {name: dict(snap) for name, snap in _STATE['snapshots'].items()}
            disp, by_id = {}, {}
            for qual, (fn, opts) in REGISTRY.items():
                new = types.FunctionType(fn.__code__, spaces[fn.__module__], fn.__name__,
                                         fn.__defaults__, fn.__closure__)
                new.__module__, new.__qualname__ = fn.__module__, fn.__qualname__
                new.__doc__ = fn.__doc__
                disp[qual] = by_id[id(fn)] = numba.njit(**opts)(new)
            for space in spaces.values():
                for attr, value in list(space.items()):
                    if id(value) in by_id:
                        space[attr] = by_id[id(value)]
            _STATE['jit'] = disp
    return _STATE['jit']


#: Pairs from which the L-BFGS calls go to the lazily built JIT (parallel) kernels: the
#: JIT path's own threshold (cost.kernels.PARALLEL_PAIRS, not imported: this module sits
#: below cost; test_aot holds the two equal). Measured on 2 shared cores, random
#: fields in a 1 km box, w 0.5, warm plan() median of 5 in one process, all serial AOT
#: against AOT + lazy JIT above these: 20 threats (800 pairs: all AOT either way) the
#: serial AOT is faster than JIT; 100 threats (4,000 pairs) 388/372 -> 314/349 ms;
#: 300 threats 1,567/1,495 -> 1,070/1,065 ms; 1,000 threats 190 -> 150 ms (prototype)
#: and 193/192 -> 180/191 ms. The lazy JIT costs its process ~0.45 s once (numba's
#: import and the cached kernels' loads: first plan at 100 threats 430 -> 906 ms).
PARALLEL_PAIRS = 4_000
#: Threats from which the edge costs (segment_costs over all pairs, the cut-off near
#: costs; parallel whatever the size on the JIT path) go to the JIT kernels too: where
#: the L-BFGS does (4,000 pairs at 40 segments), so numba is imported for large problems
#: only (a 20-threat network's near costs on the JIT kernels imported it for every plan:
#: first plan 538 ms). The 100-1,000 threat figures above were measured so.
PARALLEL_THREATS = 100


def _pairs_lbfgs(a, seg_i: int, pos_i: int, n1) -> int:
    return len(a[seg_i]) or (n1 - 1) * len(a[pos_i])


def _route(qual: str, aot):
    """Return the AOT function, or one that sends large problems to the JIT kernel."""
    name = qual.rsplit('.', 1)[1]
    if name in ('_minimise', '_rounds'):
        def pairs(a):
            return _pairs_lbfgs(a, 6, 3, len(a[0]) // 3)
        limit = PARALLEL_PAIRS
    elif name == '_objective':
        def pairs(a):
            return _pairs_lbfgs(a, 5, 2, a[1])
        limit = PARALLEL_PAIRS
    elif name in ('_segment_costs_parallel', '_near_costs'):
        def pairs(a):
            return len(a[2])
        limit = PARALLEL_THREATS
    else:
        return aot

    def routed(*a):
        if pairs(a) >= limit:
            return jit()[qual](*a)
        return aot(*a)
    routed.__name__ = routed.__qualname__ = name
    routed.__doc__ = f'{qual}: AOT (serial) below {limit}, lazily built JIT above.'
    routed.aot = aot
    return routed
