"""Where the repository, its scenarios and the bench results are, and the machine they ran on."""

from __future__ import annotations

import os
from pathlib import Path
import sys
from typing import Sequence

ROOT = Path(__file__).resolve().parents[2]
#: Results of the suites (committed).
RESULTS = ROOT / 'bench' / 'results'
#: The bundled scenarios and ``reference.json``.
DATA = ROOT / 'test' / 'data'
#: The shared scenarios (``scale*.yaml``, ``reference_box.json``), where present.
SHARED = Path('/work/shared/scenarios')


def command(suite: str, argv: Sequence[str] = ()) -> str:
    """Return the command line that runs ``suite`` with ``argv``, as results quote it."""
    return ' '.join(['python -m bench', suite, *argv])


def suite_process(suite: str, *args: str) -> list[str]:
    """Return the command running ``python -m bench suite args`` from any folder."""
    boot = (f'import sys; sys.path.insert(0, {str(ROOT)!r}); '
            'from bench.__main__ import main; sys.exit(main())')
    return [sys.executable, '-c', boot, suite, *args]


def machine() -> str:
    """Return the CPU the results were measured on: model, LLVM's name for it, cores.

    Rounding, and so a basin chosen where two are close, can differ between CPUs (numba
    compiles for the host's instruction set), so a result that must hold on every CPU
    names the one it was seen on.
    """
    model = 'unknown CPU'
    try:
        with open('/proc/cpuinfo', encoding='utf-8') as info:
            model = next(line.split(':', 1)[1].strip() for line in info
                         if line.startswith('model name'))
    except (OSError, StopIteration):
        pass
    try:
        import llvmlite.binding as llvm
        target = llvm.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - a description only
        target = '?'
    return f'{model} (LLVM target {target}, {os.cpu_count()} CPUs)'
