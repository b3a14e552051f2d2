"""The same measurement on two checkouts, taking turns, each in fresh processes.

A process that plans with another checkout must import that checkout's ``threat_planner``
before it puts this repository on ``sys.path`` for ``bench``: :data:`THEN_BENCH` is the
Python to run between the two.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import subprocess
import sys
from typing import Callable, Sequence

from bench.toolkit.repo import ROOT

#: Python that imports the checkout's package (first on the path), then makes ``bench`` of
#: this repository importable; the package stays the checkout's (``sys.modules``).
THEN_BENCH = f'import threat_planner\nimport sys\nsys.path.insert(0, {str(ROOT)!r})\n'


def short_commit(tree: Path) -> str:
    """Return the abbreviated commit of a checkout's HEAD ('' outside git)."""
    return subprocess.run(['git', '-C', str(tree), 'rev-parse', '--short', 'HEAD'],
                          capture_output=True, text=True).stdout.strip()


def describe(trees: Sequence[tuple[str, Path]], sep: str = ', ') -> str:
    """Return ``label = `commit``` of each checkout, joined by `sep`, as reports name them."""
    return sep.join(f'{label} = `{short_commit(tree)}`' for label, tree in trees)


def fresh_json(code: str, *args: object) -> object:
    """Run ``python -c code args...`` in a fresh process; the JSON of its last output line."""
    done = subprocess.run([sys.executable, '-c', code, *map(str, args)], capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def interleaved(trees: list[tuple[str, Path]], repeats: int,
                run: Callable[[Path], object]) -> dict[str, list]:
    """Call ``run(tree)`` ``repeats`` times per checkout, the order flipped every pass.

    Machine load then falls on every checkout alike. Returns ``{label: [results]}``.
    """
    runs: dict[str, list] = {label: [] for label, _ in trees}
    for i in range(max(repeats, 1)):
        for label, tree in (trees if i % 2 == 0 else trees[::-1]):
            runs[label].append(run(tree))
    return runs


def comparison_args(description: str, repeats: int, out: Path, argv: list[str] | None = None,
                    more: Callable[[argparse.ArgumentParser], None] | None = None
                    ) -> tuple[argparse.Namespace, list[tuple[str, Path]]]:
    """Parse ``--base``, ``--repeats``, ``--out``; the args and ``[(label, checkout)]``.

    The checkouts are ``('base', BASE)`` (when given) then ``('this checkout', ROOT)``.
    ``more`` adds a suite's own options to the parser.
    """
    ap = argparse.ArgumentParser(description=description)
    if more is not None:
        more(ap)
    ap.add_argument('--base', type=Path, help='another checkout to time beside this one')
    ap.add_argument('--repeats', type=int, default=repeats, help=f'passes (default {repeats})')
    ap.add_argument('--out', type=Path, default=out)
    args = ap.parse_args(argv)
    trees = [('this checkout', ROOT)]
    if args.base is not None:
        trees.insert(0, ('base', args.base.resolve()))
    return args, trees
