"""Import scipy's array-API layer without numpy's submodules that no plan uses.

Imported (for this side effect) before every ``scipy`` import of the package. scipy 1.17's
vendored array-api-compat clones numpy's namespace (``from numpy import *``, then
``getattr`` over ``dir(numpy)``), which imports numpy's lazy submodules ``f2py``,
``testing``, ``ma``, ``polynomial``, ... : 0.06-0.1 s of a 0.4 s ``threat-planner plan``
(``bench/results/cold_start.md``). While that one import runs, numpy answers those names
with a stand-in that imports the submodule on its first attribute, so the clone holds the
stand-in and nothing is loaded; numpy's own loader is back in place afterwards, and
``numpy.testing`` and the rest import as ever (a thread that reads one of those names
during that import gets the stand-in, which answers its attributes as the module does).
:func:`unmasked` keeps ``numpy.ma`` out of Qhull's masked-array check the same way.
"""

from __future__ import annotations

from contextlib import contextmanager
import importlib
import sys
import threading
from typing import Callable, Iterator

import numpy

__all__ = ['SKIPPED', 'unmasked']

#: numpy's lazy submodules left unloaded by scipy's import (not ``linalg``, ``fft``,
#: ``random`` or ``typing``, which scipy uses).
SKIPPED = frozenset({'char', 'core', 'ctypeslib', 'f2py', 'ma', 'matlib', 'polynomial',
                     'rec', 'strings', 'testing'})


class _Later:
    """numpy's submodule ``name``, imported on its first attribute."""

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attr: str) -> object:
        return getattr(importlib.import_module(f'numpy.{self._name}'), attr)


class _Unmasked(_Later):
    """``numpy.ma`` before anything imported it: no array can be masked yet."""

    @staticmethod
    def isMaskedArray(x: object) -> bool:  # noqa: N802 (numpy's name)
        ma = sys.modules.get('numpy.ma')
        return ma is not None and ma.isMaskedArray(x)


@contextmanager
def unmasked() -> Iterator[None]:
    """Within, ``numpy.ma`` answers ``isMaskedArray`` without being imported.

    scipy's Delaunay asks ``np.ma.isMaskedArray(points)`` of every input, and the first
    ask imports ``numpy.ma``: 12-14 ms of a process's first plan, for arrays the planner
    made itself. A masked array exists only once ``numpy.ma`` is loaded, so until then the
    answer is False; once it is loaded, numpy's own loader answers as ever.
    """
    with _UNMASKED['lock']:
        if _UNMASKED['depth'] == 0:
            _UNMASKED['loader'] = numpy.__dict__.get('__getattr__')
            if _UNMASKED['loader'] is not None and 'numpy.ma' not in sys.modules:
                numpy.__getattr__ = _unmasked_getattr
        _UNMASKED['depth'] += 1
    try:
        yield
    finally:
        with _UNMASKED['lock']:
            _UNMASKED['depth'] -= 1
            if _UNMASKED['depth'] == 0 and numpy.__dict__.get('__getattr__') is _unmasked_getattr:
                numpy.__getattr__ = _UNMASKED['loader']


#: numpy's loader while :func:`unmasked` is in force, and in how many threads it is.
_UNMASKED: dict = {'lock': threading.Lock(), 'depth': 0, 'loader': None}


def _unmasked_getattr(name: str) -> object:
    if name == 'ma' and 'numpy.ma' not in sys.modules:
        return _Unmasked('ma')
    return _UNMASKED['loader'](name)


def _import_array_api() -> None:
    """Import ``scipy._lib._array_api`` with numpy's SKIPPED submodules deferred."""
    if 'scipy._lib._array_api' in sys.modules:
        return
    loader: Callable[[str], object] | None = numpy.__dict__.get('__getattr__')
    if loader is None:      # another numpy: nothing loads lazily, nothing to save
        importlib.import_module('scipy._lib._array_api')
        return

    def deferred(name: str) -> object:
        if name in SKIPPED and f'numpy.{name}' not in sys.modules:
            return _Later(name)
        return loader(name)
    numpy.__getattr__ = deferred
    try:
        importlib.import_module('scipy._lib._array_api')
    finally:
        numpy.__getattr__ = loader


_import_array_api()
