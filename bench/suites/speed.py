"""Speed and quality of ``best`` with the physical limits on (the default) and off.

Writes ``bench/results/speed.md`` and ``speed.json``. Rows, side by side in one run:

* 20 threats: every bundled 20-threat scenario at w = 0.2 / 0.5 / 0.8, limits on (the
  defaults, = PHYSICAL_LIMITS) and off (NO_LIMITS), cold (a fresh plan) and warm (threats
  moved by up to 0.5 % of the box diagonal, start three segments along the last path,
  ``warm_start`` = the last plan; a refused warm start plans cold and says why).
* 1,000 and 10,000 threats: :func:`bench.toolkit.cases.scale_problem` at the 20-threat
  density, w 0.5.
* Quality: J of ``best`` with the limits on over the limited yardstick's J
  (``bench/results/yardstick.json``, SLSQP from many starts at 60 segments, same limits),
  for the cases that file holds.

Times are wall clock of ``plan()`` (kernels compiled beforehand), the median of
``--repeats`` runs per 20-threat cell (3: the plans are deterministic, so the runs differ
only by the load of the machine, which is shared; single runs moved the 20-threat median
by 20-50 % between runs of the same code); the ratios in one run mean more than the
absolute times.

Usage: ``python -m bench speed [--no-scale] [--repeats R]``
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from bench.toolkit.cases import moved_threats, scale_problem, SCENARIOS, WS
from bench.toolkit.repo import DATA, RESULTS
from bench.toolkit.timing import timed, timed_median
from threat_planner import load_scenario, plan, PlannerConfig
from threat_planner.core.cost.kernels import warm_up
from threat_planner.core.inputs.settings import NO_LIMITS, PHYSICAL_LIMITS
from threat_planner.core.optimise.limits import warm_up as warm_up_limits

TARGETS = {'20 cold median': 15.0, '20 cold worst': 40.0, '1000 cold': 250.0,
           '10000 cold': 1500.0, '20 warm median': 5.0}


def twenty_threat_rows(repeats: int = 3) -> list[dict]:
    """Cold and warm plans of every bundled 20-threat scenario, limits on and off."""
    rows = []
    for name in SCENARIOS:
        sc = load_scenario(DATA / f'{name}.yaml')
        moved = moved_threats(sc.threats, sc.box.diagonal)
        for w in WS:
            for label, lim in (('on', {}), ('off', NO_LIMITS)):
                cfg = PlannerConfig(w=w, **lim)
                cold, ms, runs = timed_median(repeats, plan, sc.threats, sc.start, sc.goal,
                                              sc.box, cfg)
                start = cold.path[3]
                warm, warm_ms, _ = timed_median(repeats, plan, moved, start, sc.goal, sc.box,
                                                cfg, warm_start=cold)
                recold, recold_ms = timed(plan, moved, start, sc.goal, sc.box, cfg)
                rows.append({
                    'case': f'{name}@{w}', 'limits': label, 'J': cold.cost.J,
                    'feasible': cold.feasible, 'ms': ms, 'ms_runs': runs, 'seed': cold.seed,
                    'worst_violation': cold.limit_check.worst,
                    'warm': warm.warm, 'warm_note': warm.warm_note, 'warm_ms': warm_ms,
                    'warm_J': warm.cost.J, 'recold_J': recold.cost.J, 'recold_ms': recold_ms})
                print(rows[-1]['case'], label, f'{ms:.0f} ms', f'J={cold.cost.J:.4f}',
                      cold.feasible, 'warm' if warm.warm else warm.warm_note,
                      f'{warm_ms:.0f} ms', flush=True)
    return rows


def scale_rows() -> list[dict]:
    """Cold plans at 1,000 and 10,000 threats, limits on and off, w 0.5."""
    rows = []
    for n in (1000, 10000):
        threats, s, t, box = scale_problem(n)
        for label, lim in (('on', {}), ('off', NO_LIMITS)):
            r, ms = timed(plan, threats, s, t, box, PlannerConfig(w=0.5, **lim))
            rows.append({'threats': n, 'limits': label, 'ms': ms, 'J': r.cost.J,
                         'feasible': r.feasible,
                         'stages': {k: round(v, 1) for k, v in r.timings_ms.items()}})
            print(n, label, f'{ms:.0f} ms', r.feasible, flush=True)
    return rows


def quality_rows(cold: list[dict]) -> list[dict]:
    """Limits-on J over the limited yardstick's, where yardstick.json has the case."""
    path = RESULTS / 'yardstick.json'
    ys = json.loads(path.read_text()) if path.exists() else {}
    ours = {r['case']: r for r in cold if r['limits'] == 'on'}
    free = {r['case']: r for r in cold if r['limits'] == 'off'}
    rows = []
    for case, entry in sorted(ys.items()):
        lim = entry.get('limited') or {}
        if case not in ours or not lim.get('feasible'):
            continue
        if {k: lim['limits'][k] for k in PHYSICAL_LIMITS} != PHYSICAL_LIMITS:
            continue
        rows.append({'case': case, 'J_on': ours[case]['J'], 'J_off': free[case]['J'],
                     'in_box': entry['in_box']['J'], 'limited': lim['J'],
                     'ratio': ours[case]['J'] / lim['J'],
                     'feasible': ours[case]['feasible']})
    return rows


def _verdict(value: float, target: float) -> str:
    return f'{"met" if value <= target else "MISSED"} ({value:.1f} vs <= {target:g} ms)'


def write_markdown(cold: list[dict], scale: list[dict], quality: list[dict],
                   repeats: int = 3) -> str:
    """Render speed.md."""
    on = [r for r in cold if r['limits'] == 'on']
    off = [r for r in cold if r['limits'] == 'off']
    warm_on = [r['warm_ms'] for r in on if r['warm']]
    warm_off = [r['warm_ms'] for r in off if r['warm']]
    lines = [
        '# Speed and quality of best, physical limits on (default) and off',
        '',
        f'Written by `python -m bench speed` on {time.strftime("%Y-%m-%d")} on a 2-core '
        'machine shared with other engineers\' jobs: absolute times are inflated and noisy; '
        f'compare the columns of one run. 20 threats: the median of {repeats} runs per cell '
        '(speed.json lists them; warm too); 1,000 and 10,000: one run; kernels compiled '
        'beforehand.',
        '',
        f'Limits on = the defaults {PHYSICAL_LIMITS} (climb / dive atan2(+-dz, horizontal), '
        'circumradius through every 3 consecutive points); off = 90 / 90 / 0.',
        'Warm = threats moved by <= 0.5 % of the box diagonal and the start moved three '
        'segments along the last path, `warm_start` = the last plan; `recold J` is a cold '
        'plan of that same moved problem. Every J is exact (closed form).',
        '',
        '## Verdicts (targets of issue 11)',
        '',
        f'* 20 threats cold, limits on, median: '
        f'{_verdict(statistics.median(r["ms"] for r in on), TARGETS["20 cold median"])}',
        f'* 20 threats cold, limits on, worst: '
        f'{_verdict(max(r["ms"] for r in on), TARGETS["20 cold worst"])}',
        f'* 20 threats cold, limits off: median {statistics.median(r["ms"] for r in off):.0f}'
        f' ms, worst {max(r["ms"] for r in off):.0f} ms (for comparison)',
    ]
    for row in scale:
        if row['limits'] == 'on':
            lines.append(f'* {row["threats"]} threats cold, limits on: '
                         + _verdict(row['ms'], TARGETS[f'{row["threats"]} cold']))
    lines.append(
        f'* warm replan at 20 threats, limits on: accepted {len(warm_on)} of {len(on)} '
        '(core/methods/warm.py: refused where the limits bound the previous plan and no second '
        'basin refined under them compares)'
        + (f', median {statistics.median(warm_on):.0f} ms: '
           + _verdict(statistics.median(warm_on), TARGETS['20 warm median'])
           if warm_on else ''))
    if warm_off:
        lines.append(f'* warm replan at 20 threats, limits off: accepted {len(warm_off)} of '
                     f'{len(off)}, median {statistics.median(warm_off):.0f} ms')
    excess = [(r['warm_J'] / r['recold_J'] - 1.0, r) for r in cold if r['warm']]
    worse = [(e, r) for e, r in excess if e > 1e-6]
    lines.append(f'* warm J <= cold J of the same problem (1e-6 relative): {len(worse)} of '
                 f'{len(excess)} warm plans above'
                 + (', by at most ' + f'{max(e for e, _ in worse):.1e} relative ('
                    + ', '.join(f'{r["case"]} {r["limits"]}' for _, r in worse) + ')'
                    if worse else ''))
    lines.append(f'* limits on, feasible: {sum(r["feasible"] for r in on)} of {len(on)}')
    if quality:
        ratios = [q['ratio'] for q in quality]
        lines.append(f'* quality vs the limited yardstick ({len(quality)} cases in '
                     f'yardstick.json): median {statistics.median(ratios):.4f}, worst '
                     f'{max(ratios):.4f}; within 1 %: {sum(x <= 1.01 for x in ratios)} of '
                     f'{len(ratios)}')
    lines += ['', '## 20 threats', '',
              '| case | limits | cold ms | J | feasible | seed | warm | warm ms | warm J '
              '| recold J |', '|---|---|---|---|---|---|---|---|---|---|']
    for r in cold:
        lines.append(
            f'| {r["case"]} | {r["limits"]} | {r["ms"]:.0f} | {r["J"]:.4f} | '
            f'{r["feasible"]} | {r["seed"]} | {"warm" if r["warm"] else r["warm_note"]} | '
            f'{r["warm_ms"]:.0f} | {r["warm_J"]:.4f} | {r["recold_J"]:.4f} |')
    if scale:
        lines += ['', '## 1,000 and 10,000 threats (scale_problem, w 0.5)', '',
                  '| threats | limits | ms | J | feasible | stages [ms] |',
                  '|---|---|---|---|---|---|']
        for r in scale:
            lines.append(f'| {r["threats"]} | {r["limits"]} | {r["ms"]:.0f} | {r["J"]:.1f} | '
                         f'{r["feasible"]} | {r["stages"]} |')
    if quality:
        lines += ['', '## Quality: limits on vs the limited yardstick', '',
                  'Yardstick: `bench/toolkit/yardstick.py` `limited_yardstick` (cached in '
                  'yardstick.json): same limits, exactly 60 near-equal segments; ours: '
                  'n_points 40.', '',
                  '| case | best, limits on | best, limits off | in-box yardstick | '
                  'limited yardstick | on / limited |', '|---|---|---|---|---|---|']
        for q in quality:
            lines.append(f'| {q["case"]} | {q["J_on"]:.3f} | {q["J_off"]:.3f} | '
                         f'{q["in_box"]:.3f} | {q["limited"]:.3f} | {q["ratio"]:.4f} |')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> None:
    """Run the rows and write the results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--no-scale', action='store_true', help='skip 1,000 / 10,000 threats')
    ap.add_argument('--repeats', type=int, default=3,
                    help='runs per 20-threat cell, the median reported (default 3)')
    args = ap.parse_args(argv)
    warm_up()
    warm_up_limits()
    # One untimed plan each way: every kernel a plan uses is compiled (or loaded) before
    # the first timed row, not only those warm_up knows.
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    for extra in ({}, NO_LIMITS):
        plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5, **extra))
    if not args.no_scale:
        # The cut-off and parallel kernels of large fields too.
        plan(*scale_problem(1000), PlannerConfig(w=0.5))
    cold = twenty_threat_rows(args.repeats)
    scale = [] if args.no_scale else scale_rows()
    quality = quality_rows(cold)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / 'speed.json').write_text(json.dumps(
        {'twenty': cold, 'scale': scale, 'quality': quality}, indent=1, default=str))
    (RESULTS / 'speed.md').write_text(write_markdown(cold, scale, quality, args.repeats))
    print((RESULTS / 'speed.md').read_text())
