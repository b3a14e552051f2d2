"""Cold plans of two checkouts on random fields that no scenario file holds, side by side.

Usage (from the repository root)::

    git worktree add /tmp/base <commit>
    .venv/bin/python bench/run_random_fields.py /tmp/base [--out bench/results/random_fields.md]

The bundled scenarios are what the planner was tuned on; these are not. Each field is
``bench_tools.scale_problem(n, 100 + seed)`` for n = 12, 20, 35, 60, 120 threats and seeds
0-2, with every intensity scaled by a random factor in [0.3, 3] and the start and goal
heights drawn uniformly in the box (so some climbs come close to the 30 deg limit), at
w = 0.2 / 0.5 / 0.8, with the flight limits on (the defaults) and off: 90 plans per
checkout. One worker process per checkout plans every field once (after one untimed
plan); each J is the checkout's own exact J of its own path.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys

ROOT = Path(__file__).resolve().parent.parent
SIZES = (12, 20, 35, 60, 120)
SEEDS = (0, 1, 2)
WS = (0.2, 0.5, 0.8)
OFF = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0}
#: J ratios beyond this either way are listed case by case.
NOTABLE = 0.002


def fields():
    """Yield ``(name, threats, start, goal, box, w)`` of every random field."""
    import numpy as np
    import bench_tools as bt
    from threat_planner.core.world.threats import ThreatField
    for n in SIZES:
        for seed in SEEDS:
            threats, s, t, box = bt.scale_problem(n, 100 + seed)
            rng = np.random.default_rng([n, seed])
            s, t = s.copy(), t.copy()
            s[2] = rng.uniform(box.lo[2], box.hi[2])
            t[2] = rng.uniform(box.lo[2], box.hi[2])
            threats = ThreatField.from_arrays(
                threats.positions, threats.intensities * rng.uniform(0.3, 3.0, len(threats)))
            for w in WS:
                yield f'n{n} seed {seed} w {w}', threats, s, t, box, w


def work(out: Path) -> None:
    """Plan every field with this process's checkout and write {case: [J, ms, feasible]}."""
    import time
    from threat_planner import plan, PlannerConfig
    sys.path.insert(0, str(Path(__file__).resolve().parent))
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
    subprocess.run([sys.executable, __file__, '--worker', str(out)], env=env, check=True,
                   cwd=tree)
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


def main() -> None:
    """Run both checkouts and write the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('base', type=Path, nargs='?', help='the other checkout (the "before")')
    ap.add_argument('--out', type=Path, default=ROOT / 'bench' / 'results' / 'random_fields.md')
    ap.add_argument('--worker', type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        work(args.worker)
        return
    if args.base is None:
        ap.error('base: the other checkout is required')
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        before = _run(args.base.resolve(), Path(tmp) / 'before.json')
        after = _run(ROOT, Path(tmp) / 'after.json')
    # Here, not at the top: a worker must import the checkout its PYTHONPATH names, and
    # _repo puts this repository first on sys.path.
    from _repo import short_commit
    rev = {'before': short_commit(args.base), 'after': short_commit(ROOT)}
    lines = ['# Random fields, before and after', '',
             f'Written by `bench/run_random_fields.py`: before = `{rev["before"]}`, after = '
             f'`{rev["after"]}`, one plan per cell on a shared 2-core machine (read the J '
             'ratios; times are indicative). Fields: see the script\'s docstring.', '']
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


if __name__ == '__main__':
    main()
