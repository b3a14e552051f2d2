"""Put the repository root on ``sys.path`` so the bench scripts import ``threat_planner``.

Imported for its side effect by every script under ``bench/`` (they run as
``python bench/<script>.py``, which puts ``bench/`` itself, not the root, on the path);
and the helpers of the reports that compare two checkouts.
"""

import argparse
import json
from pathlib import Path
import subprocess
import sys
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def short_commit(tree: Path) -> str:
    """Abbreviated commit of a checkout's HEAD ('' outside git)."""
    return subprocess.run(['git', '-C', str(tree), 'rev-parse', '--short', 'HEAD'],
                          capture_output=True, text=True).stdout.strip()


def fresh_json(code: str, *args: object) -> object:
    """Run ``python -c code args...`` in a fresh process; the JSON of its last output line."""
    done = subprocess.run([sys.executable, '-c', code, *map(str, args)], capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def interleaved(trees: list[tuple[str, Path]], repeats: int,
                run: Callable[[Path], object]) -> dict[str, list]:
    """``run(tree)`` ``repeats`` times per checkout, the order flipped every pass.

    Machine load then falls on every checkout alike. Returns ``{label: [results]}``.
    """
    runs: dict[str, list] = {label: [] for label, _ in trees}
    for i in range(max(repeats, 1)):
        for label, tree in (trees if i % 2 == 0 else trees[::-1]):
            runs[label].append(run(tree))
    return runs


def comparison_args(description: str, repeats: int, out: Path,
                    more: Callable[[argparse.ArgumentParser], None] | None = None
                    ) -> tuple[argparse.Namespace, list[tuple[str, Path]]]:
    """Parse ``--base``, ``--repeats``, ``--out``; the args and ``[(label, checkout)]``.

    The checkouts are ``('base', BASE)`` (when given) then ``('this checkout', ROOT)``.
    ``more`` adds a script's own options to the parser.
    """
    ap = argparse.ArgumentParser(description=description)
    if more is not None:
        more(ap)
    ap.add_argument('--base', type=Path, help='another checkout to time beside this one')
    ap.add_argument('--repeats', type=int, default=repeats, help=f'passes (default {repeats})')
    ap.add_argument('--out', type=Path, default=out)
    args = ap.parse_args()
    trees = [('this checkout', ROOT)]
    if args.base is not None:
        trees.insert(0, ('base', args.base.resolve()))
    return args, trees
