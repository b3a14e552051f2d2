"""The paper's own methods (``paper``, ``improved``) at 20 threats, side by side with a base.

Usage (from the repository root)::

    .venv/bin/python -m bench paper_methods [--base OTHER_CHECKOUT] [--repeats 3]

Plans every bundled 20-threat scenario at w = 0.2 / 0.5 / 0.8 with ``method`` ``paper``
(length Dijkstra, nearest entry and exit, fixed k, the mass-spring chain) and ``improved``
(J-weighted Dijkstra, candidate entries and exits, the k sweep), defaults otherwise, in a
fresh process per checkout and pass, the checkouts taking turns; one untimed plan per
method first loads the compiled kernels. Reports each checkout's median and worst of the
per-case medians and the J ratio of this checkout to the base. Writes
``bench/results/paper_methods.md``.
"""

from __future__ import annotations

import statistics
import time

from bench.toolkit.cases import SCENARIOS, WS
from bench.toolkit.checkouts import comparison_args, describe, fresh_json, interleaved
from bench.toolkit.repo import DATA, RESULTS
from bench.toolkit.report import publish

OUT = RESULTS / 'paper_methods.md'
METHODS = ('paper', 'improved')

_PASS = r'''
import json, sys, time
sys.path.insert(0, sys.argv[1])
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
cases = [(name, w, load_scenario(f'{sys.argv[2]}/{name}.yaml'))
         for name in sys.argv[3].split(',') for w in (0.2, 0.5, 0.8)]
out = {}
for method in ('paper', 'improved'):
    sc = cases[0][2]
    plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(method=method))
    for name, w, sc in cases:
        t0 = time.perf_counter()
        r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w, method=method))
        out[f'{method}:{name}@{w}'] = (1e3 * (time.perf_counter() - t0), r.cost.J)
print(json.dumps(out))
'''


def main(argv: list[str] | None = None) -> None:
    """Run the passes, alternating the checkouts, and write the table."""
    args, trees = comparison_args(__doc__.split('\n')[0], 3, OUT, argv)
    # One pass of every case in a fresh process importing the checkout: {case: [ms, J]}.
    runs = interleaved(trees, args.repeats, lambda tree: fresh_json(
        _PASS, tree, DATA, ','.join(SCENARIOS)))
    lines = ['# `paper` and `improved` at 20 threats', '',
             'Written by `python -m bench paper_methods` on '
             f'{time.strftime("%Y-%m-%d %H:%M")}: ' + describe(trees)
             + f'; {len(SCENARIOS)} bundled scenarios x w {WS}, defaults otherwise; '
             f'{args.repeats} passes per checkout in fresh processes, taking turns; ms = the '
             'median of each case over the passes (kernels loaded beforehand); a 2-core '
             'machine shared with other jobs.', '',
             '| method | checkout | median ms | worst ms | worst case |',
             '|---|---|---:|---:|---|']
    for method in METHODS:
        for label, _ in trees:
            per = {case: statistics.median(p[case][0] for p in runs[label])
                   for case in runs[label][0] if case.startswith(method + ':')}
            worst = max(per, key=per.get)
            lines.append(f'| {method} | {label} | {statistics.median(per.values()):.1f} | '
                         f'{per[worst]:.1f} | {worst.split(":", 1)[1]} |')
    if args.base is not None:
        lines.append('')
        for method in METHODS:
            ratio = [runs['this checkout'][0][c][1] / runs['base'][0][c][1]
                     for c in runs['base'][0] if c.startswith(method + ':')]
            lines.append(f'* {method}: J this checkout / base over {len(ratio)} cases: '
                         f'median {statistics.median(ratio):.9f}, least {min(ratio):.9f}, '
                         f'most {max(ratio):.9f}')
    publish(lines, args.out)
