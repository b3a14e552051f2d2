"""Where numba keeps the compiled kernels: a folder named by a hash of their contents.

Two things differ from numba's own cache (which keys a function by its source file's
absolute path and checks it against that file only):

* The folder is named by a hash of every compiled module (and of :mod:`.cost.closed_form`,
  whose constants are compiled in). The kernels call one another across files
  (:mod:`.optimise.lbfgs` inlines :mod:`.cost.kernels` and :mod:`.optimise.limit_kernels`),
  so after an edit that changed only a callee a caller's stale machine code was loaded:
  it crashed the planner with a segmentation fault twice during development.
* Inside it, a kernel's place is its module's path inside the package, not on the disk,
  so every copy of the same sources shares one cache: the editable checkout of
  ``make venv``, a colcon install, a pip install, a fresh clone. A kernel compiled once on
  this machine (``threat-planner compile``, which ``make venv`` and ``setup.py build``
  run) is loaded by all of them.

A folder that cannot be written falls back to one under the temporary directory; an
unreadable or corrupt cache file counts as a miss (the kernel compiles again), never as
an error.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import os
from pathlib import Path
import sys
import tempfile

#: The modules compiled with ``cache=True`` and the ones whose constants they compile in.
SOURCES = ('cost/closed_form.py', 'cost/pair_integrals.py', 'cost/kernels.py',
           'cost/near_kernels.py', 'cost/far_kernels.py', 'network/graph_kernels.py',
           'optimise/lbfgs.py', 'optimise/limit_kernels.py', 'optimise/lagrangian_kernels.py',
           'optimise/limits.py', 'optimise/chain_kernels.py', 'detection/kernels.py')
#: Of those, the modules with no AOT export (they import numba itself): the AOT path does
#: not import them, so a process that plans on the AOT kernels loads no numba.
JIT_ONLY = ('detection/kernels.py',)

#: Spins of an idle parallel-kernel thread before it sleeps (libgomp's GOMP_SPINCOUNT).
SPIN_COUNT = 3000

_CORE = Path(__file__).resolve().parent
_configured = False


@functools.lru_cache(maxsize=None)
def sources_digest() -> str:
    """Return the hash naming the cache folder: of :data:`SOURCES`' contents, 16 hex."""
    digest = hashlib.sha1()
    for name in SOURCES:
        digest.update(name.encode())
        digest.update((_CORE / name).read_bytes())
    return digest.hexdigest()[:16]


def cache_root() -> Path:
    """Return the base folder: ``$THREAT_PLANNER_CACHE_DIR``, ``$NUMBA_CACHE_DIR``, the user's."""
    if os.environ.get('THREAT_PLANNER_CACHE_DIR'):
        return Path(os.environ['THREAT_PLANNER_CACHE_DIR'])
    if os.environ.get('NUMBA_CACHE_DIR'):
        return Path(os.environ['NUMBA_CACHE_DIR']) / 'threat_planner'
    base = os.path.join(
        os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache'),
        'threat_planner', 'numba')
    return Path(base)


def cache_dir() -> Path:
    """Return the folder of this set of sources: :func:`cache_root` / the sources' hash."""
    return cache_root() / sources_digest()


def fallback_dir() -> Path:
    """Return the folder used where :func:`cache_dir` cannot be written."""
    uid = os.getuid() if hasattr(os, 'getuid') else 'user'
    return Path(tempfile.gettempdir()) / f'threat_planner-numba-{uid}' / sources_digest()


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
        return True
    except OSError:
        return False


def _make_locator():
    """Return the locator class (built here: numba's base classes are imported lazily)."""
    from numba.core import caching

    class PackageLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        """Cache of a kernel of this package, placed by its path inside the package."""

        def __init__(self, py_func, py_file: str, path: Path) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._path = str(path)

        def get_cache_path(self) -> str:
            return self._path

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                inner = Path(py_file).resolve().relative_to(_CORE)
            except (OSError, ValueError):
                return None  # not ours: numba's own locators take it
            for base in (cache_dir(), fallback_dir()):
                folder = base / inner.parent
                if _writable(folder):
                    return cls(py_func, py_file, folder)
            return None

    return PackageLocator


def _ours(cache_file) -> bool:
    return str(getattr(cache_file, '_cache_path', '')).startswith(
        (str(cache_root()), str(fallback_dir().parent)))


def _tolerant(method, on_error):
    """Wrap an IndexDataCacheFile method: an error on one of our files is a miss."""
    @functools.wraps(method)
    def wrapper(self, *args):
        try:
            return method(self, *args)
        except FileNotFoundError:
            raise
        except Exception:  # noqa: BLE001 - a damaged cache file must never stop a plan
            if not _ours(self):
                raise
            return on_error()
    return wrapper


def configure() -> None:
    """Put :func:`_make_locator`'s class first (before any kernel is decorated)."""
    global _configured
    if _configured:
        return
    # libgomp (numba's omp layer) reads this when the first parallel kernel loads it: its
    # threads then spin SPIN_COUNT times after a parallel loop, not 300,000, before they
    # sleep. A plan runs thousands of short loops; beside two busy processes a 1,000-
    # threat plan took 7.1 s with libgomp's spin and 0.3 s with this one, quiet 151 and
    # 153 ms (passive, no spin: 0.25 s and 182 ms; bench/results/omp_wait.md). A user's
    # own OMP_WAIT_POLICY or GOMP_SPINCOUNT stands.
    if 'OMP_WAIT_POLICY' not in os.environ:
        os.environ.setdefault('GOMP_SPINCOUNT', str(SPIN_COUNT))
    from numba.core import caching
    impl = getattr(caching, 'CacheImpl', None) or caching._CacheImpl
    impl._locator_classes = [_make_locator()] + [
        c for c in impl._locator_classes if c.__name__ != 'PackageLocator']
    files = caching.IndexDataCacheFile
    files._load_index = _tolerant(files._load_index, dict)
    files._load_data = _tolerant(files._load_data, lambda: None)
    files.save = _tolerant(files.save, lambda: None)
    _configured = True


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
