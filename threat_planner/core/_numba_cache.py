"""Where numba keeps the compiled kernels: a folder named by a hash of their sources.

numba checks a cached function against its own source file only. The kernels call one
another across files (:mod:`.lbfgs` inlines :mod:`.kernels` and :mod:`.limit_kernels`),
so after an edit or an upgrade that changed only a callee, a caller's stale machine code
was loaded: it crashed the planner with a segmentation fault twice during development.
Naming the cache folder by a hash of every compiled module (and of :mod:`.cost`, whose
constants are compiled in) makes any change start a fresh cache.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: The modules compiled with ``cache=True`` and the ones whose constants they compile in.
SOURCES = ('cost.py', 'kernels.py', 'lbfgs.py', 'limit_kernels.py', 'near_kernels.py',
           'graph_kernels.py', 'lagrangian_kernels.py', 'limits.py', 'chain_kernels.py')


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
