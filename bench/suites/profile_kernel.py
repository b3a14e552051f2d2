"""Cost of one J-and-gradient evaluation at 40 segments x 20 threats, per pair.

Usage (from the repository root)::

    .venv/bin/python -m bench profile_kernel [--base OTHER_CHECKOUT] [--out FILE]

Times :func:`threat_planner.core.cost.kernels._kernel` (the optimiser's hot path: 40-segment
rounds at 20 threats are most of a plan's compiled time) called in a compiled loop, so
that no dispatch overhead is counted, on a 40-segment path through ``uniform20_0``:

* every pair (dense), the pairs listed by segment (as a cut-off gives them) and shuffled;
* a floor: one square root and one arctangent per pair, the transcendental part of the
  closed form that no rearrangement removes (:mod:`threat_planner.core.cost.pair_integrals`:
  the difference of the two ends' atan terms is one atan of the subtended angle);
* with ``--base``, the same rows for the kernel of another checkout (a fresh process),
  interleaved with this one's so that the load of a shared machine hits both alike.

Each process times the rows in rotation and keeps each row's least time (load only adds
time); the report gives the median over ``--repeats`` processes per checkout. Writes
``bench/results/profile_kernel.txt``.
"""

from __future__ import annotations

import statistics

from bench.toolkit.checkouts import comparison_args, describe, fresh_json, interleaved
from bench.toolkit.repo import DATA, RESULTS
from bench.toolkit.report import publish

OUT = RESULTS / 'profile_kernel.txt'
CALLS = 500
#: Rotations through the rows in one process (the least time of each row kept).
ROTATIONS = 9

_TIMER = r'''
import json, math, sys, time
sys.path.insert(0, sys.argv[1])
import numba
import numpy as np
from threat_planner.core.cost.kernels import _FROZEN_C2, _FROZEN_C3, _NO_PAIRS, _kernel
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.optimise.smoothing import resample

sc = load_scenario(sys.argv[2])
pos = np.ascontiguousarray(sc.threats.positions)
f = np.ascontiguousarray(sc.threats.intensities)
rng = np.random.default_rng(0)
p = resample(np.vstack([sc.start, sc.goal]), 40) + rng.normal(0.0, 5.0, (41, 3))
p[0], p[-1] = sc.start, sc.goal
n_seg, n_thr = 40, len(pos)
seg = np.repeat(np.arange(n_seg), n_thr)
thr = np.tile(np.arange(n_thr), n_seg)
mix = rng.permutation(len(seg))


@numba.njit
def loop(p, pos, f, seg, thr, c2, c3, g, n):
    s = 0.0
    for _ in range(n):
        s += _kernel(p, pos, f, 0.5, seg, thr, c2, c3, g)
    return s


@numba.njit
def floor(p, pos, n):
    s = 0.0
    for _ in range(n):
        for a in range(p.shape[0] - 1):
            for i in range(pos.shape[0]):
                dx = p[a, 0] - pos[i, 0]
                dy = p[a, 1] - pos[i, 1]
                dz = p[a, 2] - pos[i, 2]
                h = math.sqrt(dx * dx + dy * dy + dz * dz)
                s += math.atan(dx / h)
    return s


g = np.zeros((41, 3))
rows = {
    'dense': lambda n: loop(p, pos, f, _NO_PAIRS, _NO_PAIRS, _FROZEN_C2, _FROZEN_C3, g, n),
    'pairs by segment': lambda n: loop(p, pos, f, seg, thr, _FROZEN_C2, _FROZEN_C3, g, n),
    'pairs shuffled': lambda n: loop(p, pos, f, seg[mix].copy(), thr[mix].copy(),
                                     _FROZEN_C2, _FROZEN_C3, g, n),
    'floor: sqrt + atan': lambda n: floor(p, pos, n),
}
for run in rows.values():
    run(1)
calls = int(sys.argv[3])
out = {name: math.inf for name in rows}
# Rows in rotation, the least time of each kept: bursts of load only ever add time.
for _ in range(int(sys.argv[4])):
    for name, run in rows.items():
        t0 = time.perf_counter()
        run(calls)
        out[name] = min(out[name], 1e6 * (time.perf_counter() - t0) / calls)
print(json.dumps(out))
'''


def main(argv: list[str] | None = None) -> None:
    """Time the rows, interleaving the checkouts, and write the report."""
    args, trees = comparison_args(__doc__.split('\n')[0], 5, OUT, argv)
    scenario = DATA / 'uniform20_0.yaml'
    # One pass of every row in a fresh process importing the checkout: us per evaluation.
    runs = interleaved(trees, args.repeats, lambda tree: fresh_json(
        _TIMER, tree, scenario, CALLS, ROTATIONS))
    pairs = 40 * 20
    lines = [f'# _kernel (J and gradient), 40 segments x 20 threats ({pairs} pairs), '
             f'uniform20_0; {CALLS} calls in a compiled loop, the least of {ROTATIONS} '
             f'rotations through the rows per process, median over {args.repeats} '
             'processes per checkout (interleaved); machine shared with other engineers',
             describe(trees, '; '),
             '',
             f'{"checkout":24s} {"row":22s} {"us / evaluation":>16s} {"ns / pair":>10s} '
             f'{"x floor":>8s}']
    for label, passes in runs.items():
        med = {row: statistics.median(p[row] for p in passes) for row in passes[0]}
        floor = med['floor: sqrt + atan']
        for row, us in med.items():
            lines.append(f'{label:24s} {row:22s} {us:16.1f} {1e3 * us / pairs:10.1f} '
                         f'{us / floor:8.2f}')
    publish(lines, args.out)
