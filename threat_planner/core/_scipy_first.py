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
"""

from __future__ import annotations

import importlib
import sys
from typing import Callable

import numpy

__all__ = ['SKIPPED']

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
