"""Where numba keeps the compiled kernels: a folder named by a hash of their sources.

numba checks a cached function against its own source file only. The kernels call one
another across files (:mod:`.optimise.lbfgs` inlines :mod:`.cost.kernels` and
:mod:`.optimise.limit_kernels`),
so after an edit or an upgrade that changed only a callee, a caller's stale machine code
was loaded: it crashed the planner with a segmentation fault twice during development.
Naming the cache folder by a hash of every compiled module (and of :mod:`.cost.closed_form`,
whose constants are compiled in) makes any change start a fresh cache.
"""

from __future__ import annotations

import hashlib
import importlib
import os
from pathlib import Path
import sys

#: The modules compiled with ``cache=True`` and the ones whose constants they compile in.
SOURCES = ('cost/closed_form.py', 'cost/pair_integrals.py', 'cost/kernels.py',
           'cost/near_kernels.py', 'network/graph_kernels.py', 'optimise/lbfgs.py',
           'optimise/limit_kernels.py', 'optimise/lagrangian_kernels.py', 'optimise/limits.py',
           'optimise/chain_kernels.py')


def cache_dir() -> Path:
    """Return the cache folder: ``$NUMBA_CACHE_DIR`` or the user cache, then the hash."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha1()
    for name in SOURCES:
        digest.update((here / name).read_bytes())
    base = os.environ.get('NUMBA_CACHE_DIR') or os.path.join(
        os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache'),
        'threat_planner', 'numba')
    return Path(base) / digest.hexdigest()[:16]


def configure() -> None:
    """Point numba's cache at :func:`cache_dir` (before any kernel is decorated)."""
    from numba import config
    # numba falls back to its own locations where this folder cannot be written.
    config.CACHE_DIR = str(cache_dir())


def import_numba() -> None:
    """Import numba, without ``coverage`` where no coverage measurement is running.

    numba imports ``coverage`` where it is installed (colcon-core brings it) to report
    compiled lines to a running measurement, which it does only with NUMBA_JIT_COVERAGE=1:
    50-70 ms of every process's start (``-X importtime``; 1.34 -> 1.25 s of CPU for
    importing the CLI, median of 16). Where coverage is not imported yet and that variable
    is unset, numba's import does without it; ``import coverage`` works as usual after.
    """
    block = 'coverage' not in sys.modules and not os.environ.get('NUMBA_JIT_COVERAGE')
    if block:
        sys.modules['coverage'] = None  # type: ignore[assignment]
    try:
        importlib.import_module('numba')
    finally:
        if block and sys.modules.get('coverage', 0) is None:
            del sys.modules['coverage']
