"""Cold plans of two checkouts on random fields that no scenario file holds, side by side.

Usage (from the repository root)::

    git worktree add /tmp/base <commit>
    .venv/bin/python -m bench random_fields /tmp/base [--out bench/results/random_fields.md]

The bundled scenarios are what the planner was tuned on; these are not
(:func:`bench.toolkit.cases.random_fields`). Each field is ``scale_problem(n, 100 + seed)``
for n = 12, 20, 35, 60, 120 threats and seeds 0-2, with every intensity scaled by a random
factor in [0.3, 3] and the start and goal heights drawn uniformly in the box (so some
climbs come close to the 30 deg limit), at w = 0.2 / 0.5 / 0.8, with the flight limits on
(the defaults) and off: 90 plans per checkout. One worker process per checkout plans every
field once (after one untimed plan); each J is the checkout's own exact J of its own path.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

from bench.toolkit.cases import LIMITS_OFF as OFF, random_fields as fields
# The fields' sizes, seeds and weights under this suite's names (the tests read them here).
from bench.toolkit.cases import RANDOM_SEEDS as SEEDS, RANDOM_SIZES as SIZES, WS  # noqa: F401
from bench.toolkit.checkouts import short_commit, THEN_BENCH
from bench.toolkit.repo import RESULTS, ROOT

#: J ratios beyond this either way are listed case by case.
NOTABLE = 0.002
#: A worker: plans with the checkout it runs in (its cwd and PYTHONPATH), then writes.
_WORKER = THEN_BENCH + 'from bench.suites.random_fields import work\nwork(sys.argv[1])\n'


def work(out: str | Path) -> None:
    """Plan every field with this process's checkout and write {case: [J, ms, feasible]}."""
    from threat_planner import plan, PlannerConfig
    out = Path(out)
    result = {}
    warmed = False
    for name, threats, s, t, box, w in fields():
        for limits in ('on', 'off'):
            cfg = PlannerConfig(w=w, **({} if limits == 'on' else OFF))
            if not warmed:
                plan(threats, s, t, box, cfg)
                warmed = True
            t0 = time.perf_counter()
            try:
                r = plan(threats, s, t, box, cfg)
                row = [r.cost.J, 1e3 * (time.perf_counter() - t0), bool(r.feasible)]
            except Exception as exc:  # noqa: BLE001 - a failure is a row of the table
                row = [float('nan'), 1e3 * (time.perf_counter() - t0), False, str(exc)]
            result[f'{name} {limits}'] = row
    out.write_text(json.dumps(result))


def _run(tree: Path, out: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, '-c', _WORKER, str(out)], env=env, check=True, cwd=tree)
    return json.loads(out.read_text())


def _summary(before: dict, after: dict, limits: str) -> tuple[str, list[str]]:
    keys = [k for k in before if k.endswith(' ' + limits)]
    ratios = [after[k][0] / before[k][0] for k in keys]
    t_b = statistics.median(before[k][1] for k in keys)
    t_a = statistics.median(after[k][1] for k in keys)
    infeasible = sum(not after[k][2] for k in keys)
    line = (f'* limits {limits} ({len(keys)} plans): J after/before median '
            f'{statistics.median(ratios):.5f}, best {min(ratios):.4f}, worst {max(ratios):.4f}'
            f' ({sum(r < 1 - NOTABLE for r in ratios)} lower and '
            f'{sum(r > 1 + NOTABLE for r in ratios)} higher by more than {NOTABLE:.1%}); '
            f'median time {t_b:.0f} -> {t_a:.0f} ms; infeasible after: {infeasible}')
    rows = [f'| {k} | {before[k][0]:.3f} | {after[k][0]:.3f} | {r:.4f} | '
            f'{before[k][1]:.0f} | {after[k][1]:.0f} | {after[k][2]} |'
            for k, r in zip(keys, ratios) if abs(r - 1) > NOTABLE or not after[k][2]]
    return line, rows


def main(argv: list[str] | None = None) -> None:
    """Run both checkouts and write the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('base', type=Path, help='the other checkout (the "before")')
    ap.add_argument('--out', type=Path, default=RESULTS / 'random_fields.md')
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        before = _run(args.base.resolve(), Path(tmp) / 'before.json')
        after = _run(ROOT, Path(tmp) / 'after.json')
    rev = {'before': short_commit(args.base), 'after': short_commit(ROOT)}
    lines = ['# Random fields, before and after', '',
             f'Written by `python -m bench random_fields`: before = `{rev["before"]}`, after = '
             f'`{rev["after"]}`, one plan per cell on a shared 2-core machine (read the J '
             'ratios; times are indicative). Fields: see the suite\'s docstring.', '']
    table = ['', f'Cases whose J moved by more than {NOTABLE:.1%} (or that are infeasible):',
             '', '| case | before J | after J | after/before | before ms | after ms | '
             'feasible after |', '|---|---:|---:|---:|---:|---:|---|']
    for limits in ('on', 'off'):
        line, rows = _summary(before, after, limits)
        lines.append(line)
        table += rows
    args.out.write_text('\n'.join(lines + table) + '\n')
    print('\n'.join(lines))
    print('wrote', args.out)
