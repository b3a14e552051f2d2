"""Compute the in-box and the limit-respecting yardsticks for every referenced scenario.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python -m bench yardstick --quick           # 2 small scenarios
    .venv/bin/python -m bench yardstick                   # every scenario with a reference
    .venv/bin/python -m bench yardstick --scenarios big300_0 --big-grid 25

For each scenario of ``test/data/*.yaml`` that has a ``reference.json`` entry and each
w in {0.2, 0.5, 0.8}: :func:`bench.toolkit.yardstick.in_box_yardstick` (``--grid``^3 grid,
4 routes penalised x3 plus the straight line, bounded L-BFGS-B at 20 then 60 segments) and
:func:`bench.toolkit.yardstick.limited_yardstick` (climb and dive <= ``--climb`` /
``--dive`` deg, turn radius >= ``--radius-frac`` times the box's shortest horizontal edge:
10 m on the 100 m fields, 100 m on big300_0; 60 equal-ish segments). Fields wider than
500 m use the ``--big-grid`` grid. Results are cached per ``scenario@w`` in
``bench/results/yardstick.json`` (recomputed only with ``--force`` or other settings) and
tabulated in ``bench/results/yardstick.md`` with the ratio to
``/work/shared/scenarios/reference_box.json``.
Runs split over processes (``--out`` elsewhere) are folded in with ``--merge OTHER.json``;
``--table-only`` just rewrites the table from the cache.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
from pathlib import Path
import platform
import sys

import numpy as np

from bench.toolkit import yardstick as ys
from bench.toolkit.cases import QUICK_SCENARIOS, WS
from bench.toolkit.grid import build_grid
from bench.toolkit.repo import DATA, RESULTS, SHARED
from threat_planner.core.inputs.scenario import load_scenario

REFERENCE_BOX = SHARED / 'reference_box.json'


def _settings(args: argparse.Namespace, grid: int, radius: float) -> dict:
    return {'grid': grid, 'routes': 4, 'penalty': 3.0, 'coarse': 20, 'fine': 60,
            'n_segments': args.segments, 'spacing': args.spacing, 'max_climb_deg': args.climb,
            'max_dive_deg': args.dive, 'min_turn_radius_m': radius,
            # Cases cached under the circumradius rule (no key) are computed again.
            'turn_radius': 'fillet'}


def run_case(sc, w: float, graph, settings: dict) -> dict:
    """Both yardsticks of one scenario at one w, as a JSON-ready dict."""
    inb = ys.in_box_yardstick(sc.threats, sc.start, sc.goal, sc.box, w, graph=graph,
                              routes=settings['routes'], penalty=settings['penalty'],
                              coarse=settings['coarse'], fine=settings['fine'])
    lim = ys.limited_yardstick(sc.threats, sc.start, sc.goal, sc.box, w,
                               settings['max_climb_deg'], settings['max_dive_deg'],
                               settings['min_turn_radius_m'],
                               n_segments=settings['n_segments'],
                               spacing=settings['spacing'], in_box=inb)
    return {'settings': settings,
            'in_box': {'J': inb['J'], 'seconds': inb['seconds'], 'how': inb['how'],
                       'n_segments': inb['n_segments'], 'grid_build_s': inb['grid_build_s'],
                       'candidates': [{k: c[k] for k in ('how', 'n_segments', 'J_seed', 'J')}
                                      for c in inb['candidates']],
                       'path': np.asarray(inb['path']).tolist()},
            'limited': {'J': lim['J'], 'seconds': lim['seconds'], 'how': lim['how'],
                        'feasible': lim['feasible'], 'limits': lim['limits'],
                        'achieved': lim['achieved'], 'n_segments': lim['n_segments'],
                        'spacing': lim['spacing'], 'starts': lim['starts'],
                        'path': np.asarray(lim['path']).tolist()}}


def write_markdown(results: dict, out: Path) -> None:
    """Write the yardstick table."""
    ref_box = json.loads(REFERENCE_BOX.read_text()) if REFERENCE_BOX.exists() else {}
    ref = json.loads((DATA / 'reference.json').read_text())
    lines = [
        '# In-box yardsticks', '',
        f'Written by `python -m bench yardstick` on {dt.date.today()} ({platform.node()}, '
        'a 2-core machine shared with other jobs: seconds are indicative only).', '',
        'Rules of every row (all J exact, closed form, `path_cost`):', '',
        '* **in-box J**: no flight limits, every vertex inside the box. G^3 26-connected grid '
        '(G in the table), Dijkstra on exact edge J, 4 routes (edges of earlier routes x3) '
        'plus the straight line, each resampled to 20 equal segments and refined by bounded '
        'L-BFGS-B on the exact J and gradient, the best two again at 60 segments; lowest kept.',
        '* **ratio box**: in-box J / `reference_box.json` J (computed elsewhere by the same '
        'recipe with 32-point Gauss-Legendre in the optimiser); < 1 means ours is lower.',
        '* **ratio lb**: in-box J / `reference.json` J (unbounded refinement, leaves the box: a '
        'lower bound, >= 1 expected).',
        '* **limited J**: inside the box AND climb <= C deg, dive <= D deg (atan2(+-dz, '
        'horizontal length) per segment), circumradius through every interior vertex and its '
        'neighbours >= R m (collinear = infinite), checked by an independent function to '
        '1e-6. Exactly 60 segments, each within [L0/1.5, 1.5 L0] (L0 = start length / 60), so '
        'the radius rule acts at a fixed, stated resolution. SLSQP (exact J gradient, '
        'complex-step constraint Jacobian) from each in-box candidate and the straight line, '
        'a quadratic-penalty L-BFGS-B continuation where SLSQP ends infeasible; lowest '
        'feasible kept. R = 0.1 x the shortest horizontal box edge (10 m on 100 m fields).',
        '* **seconds**: in-box (grid build counted in each w of a scenario) + limited.', '',
        '* **starts**: feasible limited starts / all, and the worst feasible start\'s J over '
        'the best (the limited problem has several local optima).', '',
        '| case | G | in-box J | ratio box | ratio lb | limited J | limited / in-box '
        '| limits C/D/R | achieved C/D/R | starts | seconds |',
        '|---|---|---|---|---|---|---|---|---|---|---|']

    def ratio(value: float, base: float | None, digits: int = 4) -> str:
        return f'{value / base:.{digits}f}' if base else '-'

    for key in sorted(results):
        r = results[key]
        inb, lim, st = r['in_box'], r['limited'], r['settings']
        a = lim['achieved']
        feas = [s['J'] for s in lim['starts'] if s['feasible']]
        spread = f'{max(feas) / min(feas):.3f}' if feas else '-'
        lines.append(
            f"| {key} | {st['grid']} | {inb['J']:.3f} "
            f"| {ratio(inb['J'], ref_box.get(key, {}).get('J'), 5)} "
            f"| {ratio(inb['J'], ref.get(key, {}).get('J'))} "
            f"| {lim['J']:.3f} | {ratio(lim['J'], inb['J'])} "
            f"| {st['max_climb_deg']:g}/{st['max_dive_deg']:g}/{st['min_turn_radius_m']:g} "
            f"| {a['max_climb_deg']:.2f}/{a['max_dive_deg']:.2f}/{a['min_turn_radius_m']:.2f} "
            f"| {len(feas)}/{len(lim['starts'])}, {spread} "
            f"| {inb['seconds']:.0f} + {lim['seconds']:.0f} |")
    out.write_text('\n'.join(lines) + '\n')


def main(argv: list[str] | None = None) -> int:
    """Run the yardsticks; return the exit status."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--quick', action='store_true', help=f'only {", ".join(QUICK_SCENARIOS)}')
    p.add_argument('--scenarios', nargs='+', help='scenario names (default: all referenced)')
    p.add_argument('--grid', type=int, default=41, help='grid nodes per axis (default 41)')
    p.add_argument('--big-grid', type=int, default=25,
                   help='grid nodes per axis on fields wider than 500 m (default 25)')
    p.add_argument('--climb', type=float, default=30.0, help='max climb [deg]')
    p.add_argument('--dive', type=float, default=30.0, help='max dive [deg]')
    p.add_argument('--radius-frac', type=float, default=0.1,
                   help='min turn radius / shortest horizontal box edge (default 0.1)')
    p.add_argument('--segments', type=int, default=60, help='segments of the limited path')
    p.add_argument('--spacing', type=float, default=1.5, help='segment length spread')
    p.add_argument('--force', action='store_true', help='recompute cached cases')
    p.add_argument('--merge', type=Path, nargs='+', default=[],
                   help="other runs' yardstick.json to fold into the cache first")
    p.add_argument('--table-only', action='store_true', help='only rewrite yardstick.md')
    p.add_argument('--out', type=Path, default=RESULTS)
    args = p.parse_args(argv)
    ref = json.loads((DATA / 'reference.json').read_text())
    names = sorted({k.rpartition('@')[0] for k in ref})
    if args.quick:
        names = list(QUICK_SCENARIOS)
    if args.scenarios:
        names = args.scenarios
    args.out.mkdir(parents=True, exist_ok=True)
    cache_path = args.out / 'yardstick.json'
    results = json.loads(cache_path.read_text()) if cache_path.exists() else {}
    for other in args.merge:
        results.update(json.loads(other.read_text()))
    if args.merge:
        cache_path.write_text(json.dumps(results, indent=1, allow_nan=True))
    for name in [] if args.table_only else names:
        sc = load_scenario(DATA / f'{name}.yaml')
        span = sc.box.hi - sc.box.lo
        grid = args.big_grid if float(span.max()) > 500.0 else args.grid
        radius = args.radius_frac * float(min(span[0], span[1]))
        settings = _settings(args, grid, radius)
        todo = [w for w in WS if args.force or results.get(f'{name}@{w}', {})
                .get('settings') != settings]
        if not todo:
            continue
        graph = build_grid(sc.threats, sc.start, sc.goal, sc.box, n=grid)
        for w in todo:
            key = f'{name}@{w}'
            results[key] = run_case(sc, w, graph, settings)
            r = results[key]
            print(f"{key}: in-box J {r['in_box']['J']:.3f} ({r['in_box']['seconds']:.0f} s), "
                  f"limited J {r['limited']['J']:.3f} ({r['limited']['seconds']:.0f} s)",
                  flush=True)
            cache_path.write_text(json.dumps(results, indent=1, allow_nan=True))
            write_markdown(results, args.out / 'yardstick.md')
    write_markdown(results, args.out / 'yardstick.md')
    bad = [k for k, r in results.items() if not math.isfinite(r['limited']['J'])]
    if bad:
        print(f'no feasible limited path for {", ".join(bad)}', file=sys.stderr)
    return 0
