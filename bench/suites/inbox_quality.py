"""In-box quality of ``best`` with the angle limits off, against the in-box yardstick.

For every bundled scenario with an entry in ``reference_box.json`` (a 41^3 grid Dijkstra on
exact edge J, alternative routes and the line, each refined by bounded L-BFGS-B inside the
box: see ``/work/shared/scenarios/README.md``) and w = 0.2 / 0.5 / 0.8, plan with
``method='best'``, ``max_pitch_deg=90``, ``max_turn_deg=180`` (limits off, the yardstick's
rules) and the path confined to the box, and write J, J / yardstick J and the time of one
plan to ``bench/results/inbox_quality.md`` (and ``.json``). Every J is the exact closed form.
The yardstick's own paths are checked to lie in the box and re-scored with the library's cost.

Usage: ``python -m bench inbox_quality [--only before|after] [--out NAME] [--repeats R]``.
``--only before`` runs without the extra seeds of :mod:`threat_planner.core.network.seeds`
only, ``--only after`` with them only.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
import time

import numpy as np

from bench.toolkit.cases import NO_ANGLE_LIMITS as LIMITS_OFF
from bench.toolkit.repo import DATA, RESULTS, SHARED
from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan, PlannerConfig

SCENARIOS = ('uniform20_0', 'uniform20_1', 'clustered_0', 'coplanar_0', 'ground_0',
             'strongweak_0', 'weak20_0', 'big300_0')
W_VALUES = (0.2, 0.5, 0.8)


def _yardstick(key: str, sc, w: float, ref: dict) -> float:
    """Return the yardstick's J, re-scored from its stored path, checked in the box."""
    path = np.load(SHARED / 'reference_box' / f'{key}.npy')
    tol = 1e-6 * sc.box.diagonal
    assert np.all(path >= sc.box.lo - tol) and np.all(path <= sc.box.hi + tol), key
    j = path_cost(path, sc.threats.positions, sc.threats.intensities, w).J
    assert abs(j - ref[key]['J']) <= 1e-6 * abs(j), (key, j, ref[key]['J'])
    return j


def run(seeds: bool, repeats: int, n_points: int) -> list[dict]:
    """Plan every case; return one row per (scenario, w)."""
    ref = json.loads((SHARED / 'reference_box.json').read_text())
    rows = []
    for name in SCENARIOS:
        sc = load_scenario(DATA / f'{name}.yaml')
        for w in W_VALUES:
            key = f'{name}@{w}'
            yard = _yardstick(key, sc, w, ref)
            cfg = replace(PlannerConfig(w=w, method='best', n_points=n_points), **LIMITS_OFF)
            if not seeds:
                cfg = replace(cfg, surface_seeds=False)
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
                times.append(1e3 * (time.perf_counter() - t0))
            inside = bool(np.all(r.path >= sc.box.lo - 1e-9)
                          and np.all(r.path <= sc.box.hi + 1e-9))
            rows.append({'scenario': name, 'w': w, 'n_threats': len(sc.threats),
                         'J': r.cost.J, 'yardstick': yard, 'ratio': r.cost.J / yard,
                         'ms': float(np.median(times)), 'seed': r.seed, 'in_box': inside})
            print(f'{key:18s} J={r.cost.J:11.3f} yard={yard:11.3f} ratio={r.cost.J / yard:.4f} '
                  f'{rows[-1]["ms"]:7.0f} ms  seed={r.seed}', flush=True)
    return rows


def markdown(runs: dict[str, list[dict]], n_points: int) -> str:
    """Side-by-side table of the runs (same cases, same machine, one after the other)."""
    labels = list(runs)
    first = runs[labels[0]]
    head = ['scenario', 'w', 'N', 'yardstick J']
    head += [f'{lab}: {c}' for lab in labels for c in ('J', 'ratio', 'ms')]
    lines = ['# In-box quality of `best`, angle limits off', '',
             'Rules of every row: path confined to the flight box, max_pitch_deg = 90, '
             f'max_turn_deg = 180 (limits off), n_points = {n_points}; yardstick = '
             '`/work/shared/scenarios/reference_box.json` (41^3 grid Dijkstra on exact edge J, '
             'routes + line refined by bounded L-BFGS-B at 60 segments; its paths re-scored '
             'here and checked inside the box). Every J is the exact closed form. Times are '
             'the median wall time of one `plan()` call on a 2-core machine shared with other '
             'engineers: compare the columns side by side, not with other files.', '',
             '| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for i, row in enumerate(first):
        cells = [row['scenario'], f"{row['w']:.1f}", str(row['n_threats']),
                 f"{row['yardstick']:.2f}"]
        for lab in labels:
            r = runs[lab][i]
            cells += [f"{r['J']:.2f}", f"{r['ratio']:.4f}", f"{r['ms']:.0f}"]
        lines.append('| ' + ' | '.join(cells) + ' |')
    lines += ['', '| run | median ratio | worst ratio | cases > 1.002 | median ms | worst ms |',
              '|---|---|---|---|---|---|']
    for lab in labels:
        ratios = np.array([r['ratio'] for r in runs[lab]])
        ms = np.array([r['ms'] for r in runs[lab]])
        lines.append(f'| {lab} | {np.median(ratios):.4f} | {ratios.max():.4f} | '
                     f'{int(np.sum(ratios > 1.002))} of {len(ratios)} | {np.median(ms):.0f} | '
                     f'{ms.max():.0f} |')
    lines += ['', 'Target (issue 11): median ratio <= 1.002 and worst <= 1.02.', '']
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> None:
    """Run with and without the extra seeds (or one of them) and write the results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--repeats', type=int, default=1)
    ap.add_argument('--n-points', type=int, default=40)
    ap.add_argument('--only', choices=('before', 'after'), help='run one variant only')
    ap.add_argument('--out', default='inbox_quality')
    args = ap.parse_args(argv)
    runs = {}
    for label, seeds in (('without seeds', False), ('with seeds', True)):
        if args.only and (args.only == 'after') != seeds:
            continue
        print(f'--- {label}', flush=True)
        runs[label] = run(seeds, args.repeats, args.n_points)
    (RESULTS / f'{args.out}.json').write_text(json.dumps(runs, indent=1))
    (RESULTS / f'{args.out}.md').write_text(markdown(runs, args.n_points))
    print(f'written {RESULTS / args.out}.md')
