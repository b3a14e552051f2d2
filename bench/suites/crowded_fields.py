"""``best`` on fresh crowded fields against the bench's in-box yardstick, beside a base.

Usage (from the repository root)::

    .venv/bin/python -m bench crowded_fields [--base OTHER_CHECKOUT] [--repeats 2]
    .venv/bin/python -m bench crowded_fields --fields random   # the 45 random fields

With ``--fields random`` the cases are the 45 random fields of the ``random_fields`` suite
(12-120 threats at the 20-threat scenarios' density, intensities x 0.3-3), cached in
``random_yardstick.json`` and written to ``random_yardstick.md``.

The shared big300_0 is one crowded field; tuning on it alone would tune to a file. Here six
fields are drawn like it (seeds 1-6): 300 threats uniform in [50, 950]^3 m of a 1 km box,
F uniform in [1e9, 4e9], start (0, 0, 500) and goal (1000, 1000, 500); w = 0.2 / 0.5 / 0.8.
Each case's yardstick is :func:`bench.toolkit.yardstick.in_box_yardstick` on a 31^3 grid (no flight
limits, inside the box; about a minute a case), computed once and cached with its path in
``bench/results/crowded_yardstick.json`` (``--rebuild`` recomputes; the stored J is checked
against ``path_cost`` of the stored path, and the path against the box). ``best`` plans
with the limits off (the yardstick's rules) and with the defaults, in a fresh process per
checkout and pass, the checkouts taking turns; ms = the least of the passes. Writes
``bench/results/crowded_fields.md``.
"""

from __future__ import annotations

import json
from pathlib import Path
import statistics
import sys
import time

import numpy as np

from bench.toolkit.checkouts import comparison_args, describe, fresh_json, interleaved
from bench.toolkit.repo import RESULTS, ROOT
from bench.toolkit.report import publish

OUT = RESULTS / 'crowded_fields.md'
CACHE = RESULTS / 'crowded_yardstick.json'
RANDOM_OUT = RESULTS / 'random_yardstick.md'
RANDOM_CACHE = RESULTS / 'random_yardstick.json'
GRID = 31

_FIELD = r'''
def field(seed):
    import numpy as np
    from threat_planner.core.world.threats import Box, ThreatField
    rng = np.random.default_rng([seed, 300, 77])
    positions = rng.uniform(50.0, 950.0, (300, 3))
    intensities = rng.uniform(1e9, 4e9, 300)
    return (ThreatField.from_arrays(positions, intensities), np.array([0.0, 0.0, 500.0]),
            np.array([1000.0, 1000.0, 500.0]), Box.from_corners([0.0] * 3, [1000.0] * 3))
'''

_CASES = _FIELD + r'''
def cases(fields):
    """(key, threats, start, goal, box, w) of every case of a field set."""
    if fields == 'random':
        from bench.toolkit.cases import random_fields   # after the checkout's package
        yield from random_fields()
        return
    for seed in range(1, 7):
        threats, s, t, box = field(seed)
        for w in (0.2, 0.5, 0.8):
            yield f'{seed}@{w}', threats, s, t, box, w
'''

_PASS = r'''
import json, sys, time
sys.path.insert(0, sys.argv[1])
from threat_planner.core.planner import plan, PlannerConfig
sys.path.insert(0, sys.argv[3])
''' + _CASES + r'''
OFF = {'max_climb_deg': 90.0, 'max_dive_deg': 90.0, 'min_turn_radius_m': 0.0}
out = {}
for key, threats, s, t, box, w in cases(sys.argv[2]):
    for rules, extra in (('off', OFF), ('on', {})):
        cfg = PlannerConfig(w=w, **extra)
        if not out:
            plan(threats, s, t, box, cfg)   # loads the compiled kernels
        t0 = time.perf_counter()
        r = plan(threats, s, t, box, cfg)
        out[f'{rules}:{key}'] = (1e3 * (time.perf_counter() - t0), r.cost.J, bool(r.feasible))
print(json.dumps(out))
'''


def _yardsticks(fields: str, cache_path: Path, rebuild: bool) -> dict:
    """Return the cached yardstick of every case, computed where missing (or all: rebuild)."""
    from bench.toolkit.yardstick import in_box_yardstick
    from threat_planner.core.cost.closed_form import path_cost
    scope: dict = {}
    exec(_CASES, scope)
    cache = {} if rebuild or not cache_path.exists() else json.loads(cache_path.read_text())
    for key, threats, s, t, box, w in scope['cases'](fields):
        if key not in cache:
            print(f'yardstick {key} ...', file=sys.stderr, flush=True)
            ys = in_box_yardstick(threats, s, t, box, w, grid=GRID)
            cache[key] = {'J': ys['J'], 'how': ys['how'], 'seconds': ys['seconds'],
                          'path': np.asarray(ys['path']).tolist()}
            cache_path.write_text(json.dumps(cache))
        path = np.array(cache[key]['path'])
        tol = 1e-6 * box.diagonal
        assert np.all(path >= box.lo - tol) and np.all(path <= box.hi + tol), key
        j = path_cost(path, threats.positions, threats.intensities, w).J
        assert abs(j / cache[key]['J'] - 1.0) < 1e-9, (key, j, cache[key]['J'])
    return cache


def main(argv: list[str] | None = None) -> None:
    """Build or read the yardsticks, run the passes and write the table."""
    def more(ap):
        ap.add_argument('--rebuild', action='store_true',
                        help='recompute every cached yardstick')
        ap.add_argument('--fields', choices=('crowded', 'random'), default='crowded',
                        help="the six crowded fields, or run_random_fields' 45 cases")
    args, trees = comparison_args(__doc__.split('\n')[0], 2, OUT, argv, more)
    random = args.fields == 'random'
    out = args.out if args.out != OUT or not random else RANDOM_OUT
    yard = _yardsticks(args.fields, RANDOM_CACHE if random else CACHE, args.rebuild)
    runs = interleaved(trees, args.repeats, lambda tree: fresh_json(
        _PASS, tree, args.fields, ROOT))
    labels = [label for label, _ in trees]
    title = ("`best` on run_random_fields' fields (12-120 threats)" if random else
             '`best` on crowded fields (300 threats, 1 km box)')
    lines = [f'# {title}', '',
             f'Written by `python -m bench crowded_fields --fields {args.fields}` on '
             f'{time.strftime("%Y-%m-%d %H:%M")}: ' + describe(trees)
             + f'; {args.repeats} passes per checkout in fresh processes, taking turns; ms = '
             'the least of the passes; a 2-core machine shared with other jobs. Fields and '
             'yardstick: see the suite. Ratios are J / the in-box yardstick (limits off, '
             f'{GRID}^3 grid); the limits-on rows (the defaults: climb and dive 30 deg, turn '
             'radius 10 m) are held to more than '
             'the yardstick, so their ratios say how much the limits cost, not a gap.', '',
             '| case | yardstick J | ' + ' | '.join(
                 f'{lab}: off | {lab}: off ms | {lab}: on | {lab}: on ms' for lab in labels)
             + ' |', '|---|---:|' + '---:|' * 4 * len(labels)]
    summary = {}
    for key in (k.split(':', 1)[1] for k in runs[labels[0]][0] if k.startswith('off:')):
        row = f'| {key} | {yard[key]["J"]:.2f} |'
        for lab in labels:
            for rules in ('off', 'on'):
                cell = [p[f'{rules}:{key}'] for p in runs[lab]]
                ratio = cell[0][1] / yard[key]['J'] if cell[0][2] else float('inf')
                ms = min(c[0] for c in cell)
                summary.setdefault((lab, rules), []).append((ratio, ms))
                row += f' {ratio:.4f} | {ms:.0f} |'
        lines.append(row)
    lines += ['', '| checkout | rules | median ratio | worst ratio | median ms |',
              '|---|---|---:|---:|---:|']
    for (lab, rules), vals in summary.items():
        ratios = [v[0] for v in vals]
        lines.append(f'| {lab} | limits {rules} | {statistics.median(ratios):.4f} | '
                     f'{max(ratios):.4f} | {statistics.median(v[1] for v in vals):.0f} |')
    lines += ['', 'Target (issue 11, limits off): median <= 1.002, worst <= 1.02.']
    publish(lines, out)
