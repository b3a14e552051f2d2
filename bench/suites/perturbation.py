"""How far J moves when every threat moves by 1 nm, 1 um or 1 mm: the plans' continuity.

Usage (from the repository root)::

    .venv/bin/python -m bench perturbation [--limits on off] [--tree CHECKOUT]
        [--out bench/results/perturbation.md] [--json bench/results/perturbation.json]

A nanometre or a micrometre is far below any measurement of a radar's position, and a
millimetre is a track's jitter: a plan that jumps with them jumps with rounding (another
CPU, libm or kernel arithmetic) or with noise. Each case (the 21 bundled 20-threat cases
and the random fields suite's 45 fresh fields) is planned cold as given and, for every size
in MOVES, SEEDS times with every threat moved that far in random directions (seeded).
The report gives each J(moved) / J(given); the target (issue 28) is every ratio at most
1 + WORSE (within 0.1 % or lower). Both J are exact; the moved field is another problem
by that distance, so beyond ~size / diagonal relative a change of J is the planner taking
another basin or stopping elsewhere, not the cost changing.

Warm replans too, as a node replans in its loop: every moved field is planned again with
``warm_start`` = the plan as given, against the same target; and for the first 1 mm field
the report counts where the warm start applied and where its J stayed within 1e-6 of the
cold plan of that field or below.

``--tree`` plans with another checkout's ``threat_planner`` (e.g. a ``git worktree`` of
an older commit, for a before / after pair of reports written by this one suite): the
package is imported only once ``main`` has put that checkout first on ``sys.path``.

``--arithmetic other`` plans in a child process on another machine's arithmetic, as far as
one machine can give it (:data:`OTHER_ARITHMETIC`: numpy's AVX2 loops instead of AVX-512,
OpenBLAS's Haswell kernels, numba's JIT for a generic x86-64): the issue asks for the
target on every CPU one can test on, and a plan that jumps with rounding jumps there.
``--against ROWS`` (another run's ``--json``) adds each case's unmoved J on both sides.

``--quality BASE`` writes instead the quality gate of issue 28 (QUALITY_OUT): every bundled
scenario (``test/data/*.yaml``, airspace ones with their zones and terrain) at w 0.2 / 0.5
/ 0.8, limits on and off (``big300_0`` off only), planned by BASE and by this checkout,
each in a process of its own, J before and after side by side.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import statistics
import sys
import time

import numpy as np

from bench.toolkit.checkouts import short_commit
from bench.toolkit.repo import machine, RESULTS, ROOT
from bench.toolkit.timing import timed

OUT = RESULTS / 'perturbation.md'
OTHER_OUT = RESULTS / 'perturbation_other_arithmetic.md'
#: The environment of ``--arithmetic other``, read before numpy, OpenBLAS and numba load.
OTHER_ARITHMETIC = {'NPY_DISABLE_CPU_FEATURES': 'X86_V4 AVX512_ICL AVX512_SPR',
                    'OPENBLAS_CORETYPE': 'Haswell', 'NUMBA_CPU_NAME': 'generic',
                    'THREAT_PLANNER_AOT': '0'}
QUALITY_OUT = RESULTS / 'perturbation_quality.md'
#: A bundled plan counts as higher when J rose by more than this fraction (the gate).
QUALITY_SLACK = 1e-6
#: How far every threat moves [m], and the fields per size.
MOVES = (1e-9, 1e-6, 1e-3)
SEEDS = 3
#: A plan is "worse" when J(moved) > (1 + WORSE) J(given); "moved" when |ratio - 1| > it.
WORSE = 1e-3
#: A warm J counts as no higher than the cold plan's within this relative slack.
WARM_SLACK = 1e-6
#: Kept for callers of the first version (the 1 nm move).
NUDGE = MOVES[0]


def cases():
    """Yield (name, threats, start, goal, box, w) of the bundled and the fresh cases."""
    from bench.toolkit.cases import bundled_cases, random_fields
    yield from bundled_cases()
    yield from random_fields()


def nudged(threats, seed: int, size: float = NUDGE):
    """Return the field with every threat moved ``size`` [m] in a random direction."""
    from threat_planner.core.world.threats import ThreatField
    d = np.random.default_rng(seed).normal(size=threats.positions.shape)
    d *= size / np.linalg.norm(d, axis=1)[:, None]
    return ThreatField.from_arrays(threats.positions + d, threats.intensities)


def run(limits: tuple[str, ...] = ('on',)) -> list[dict]:
    """Plan every case as given, moved and warm after the largest move."""
    from threat_planner import plan, PlannerConfig
    from threat_planner.core.inputs.settings import NO_LIMITS
    rows = []
    for k, (name, threats, s, t, box, w) in enumerate(cases()):
        for label in limits:
            cfg = PlannerConfig(w=w, **({} if label == 'on' else NO_LIMITS))
            given, ms = timed(plan, threats, s, t, box, cfg)
            row = {'case': name, 'limits': label, 'J': given.cost.J, 'ms': ms,
                   'seed': given.seed, 'ratios': {}, 'seeds_moved': {}}
            loop = []
            for size in MOVES:
                fields = [nudged(threats, SEEDS * k + i, size) for i in range(SEEDS)]
                others = [timed(plan, field, s, t, box, cfg) for field in fields]
                row['ratios'][f'{size:g}'] = [o.cost.J / given.cost.J for o, _ in others]
                row['seeds_moved'][f'{size:g}'] = [o.seed for o, _ in others]
                row.setdefault('ms_moved', []).extend(ms for _, ms in others)
                # The same fields replanned as the node does, from the plan before them.
                loop += [timed(plan, field, s, t, box, cfg, warm_start=given)
                         for field in fields]
            row['loop_ratios'] = [o.cost.J / given.cost.J for o, _ in loop]
            row['loop_warm'] = [bool(o.warm) for o, _ in loop]
            row['loop_ms'] = [ms for _, ms in loop]
            # The first 1 mm field's: its warm J against the cold plan of that field.
            warm, warm_ms = loop[(len(MOVES) - 1) * SEEDS]
            cold_j = row['ratios'][f'{MOVES[-1]:g}'][0] * given.cost.J
            row.update(warm=warm.warm, warm_note=warm.warm_note, warm_ms=warm_ms,
                       warm_J=warm.cost.J, cold_J=cold_j)
            rows.append(row)
            print(name, label, *(' '.join(f'{x:.4f}' for x in r)
                                 for r in row['ratios'].values()),
                  'warm' if warm.warm else warm.warm_note, flush=True)
    return rows


def _all(row: dict) -> list[float]:
    return [x for r in row['ratios'].values() for x in r]


def _warm_ok(row: dict) -> bool:
    return row['warm'] and row['warm_J'] <= (1.0 + WARM_SLACK) * row['cold_J']


def markdown(rows: list[dict], commit: str = '', arithmetic: str = 'host',
             against: list[dict] | None = None) -> str:
    """Render perturbation.md (``against``: the host's rows, for the unmoved J's table)."""
    sizes = list(rows[0]['ratios']) if rows else []
    other = arithmetic != 'host'
    how = (' with `--arithmetic other` (' + ', '.join(f'{k}={v}' for k, v in
                                                      OTHER_ARITHMETIC.items()) + ')'
           if other else '')
    lines = ['# J under 1 nm, 1 um and 1 mm moves of every threat', '',
             f'Written by `python -m bench perturbation`{how} on {time.strftime("%Y-%m-%d")} '
             f'(`{commit}`) on {machine()}. Every threat moved by the size in a random direction, '
             f'{SEEDS} such fields per case and size; cold plans of `best`; ratio = '
             'J(moved) / J(given), both exact. Worse = ratio above '
             f'{1 + WORSE:g} (the target: none); moved = |ratio - 1| above {WORSE:g}. A '
             'ratio away from 1 is the planner ending in another basin or elsewhere in '
             'one: a change of rounding (CPU, libm, kernel arithmetic) does the same.', '',
             '| limits | move [m] | cases | cases worse | cases moved | plans up | '
             'plans down | median | least | largest |',
             '|---|---|---:|---:|---:|---:|---:|---:|---:|---:|']
    for label in ('on', 'off'):
        mine = [row for row in rows if row['limits'] == label]
        for size in sizes if mine else ():
            r = [x for row in mine for x in row['ratios'][size]]
            worse = sum(any(x > 1 + WORSE for x in row['ratios'][size]) for row in mine)
            moved = sum(any(abs(x - 1) > WORSE for x in row['ratios'][size]) for row in mine)
            lines.append(f'| {label} | {size} | {len(mine)} | {worse} | {moved} | '
                         f'{sum(x > 1 + WORSE for x in r)} | {sum(x < 1 - WORSE for x in r)} '
                         f'| {statistics.median(r):.4f} | {min(r):.4f} | {max(r):.4f} |')
    lines += ['', '## Warm replans after the 1 mm move', '',
              '| limits | cases | bundled cases | warm | bundled warm | warm J <= cold J '
              f'(+{WARM_SLACK:g}) | bundled, warm and <= cold | median warm ms |',
              '|---|---:|---:|---:|---:|---:|---:|---:|']
    for label in ('on', 'off'):
        mine = [row for row in rows if row['limits'] == label]
        if not mine:
            continue
        bundled = [row for row in mine if '@' in row['case']]
        times = [row['warm_ms'] for row in mine if row['warm']]
        lines.append(f'| {label} | {len(mine)} | {len(bundled)} | '
                     f'{sum(row["warm"] for row in mine)} | '
                     f'{sum(row["warm"] for row in bundled)} | '
                     f'{sum(_warm_ok(row) for row in mine)} | '
                     f'{sum(_warm_ok(row) for row in bundled)} | '
                     f'{statistics.median(times) if times else float("nan"):.1f} |')
    lines += loop_table(rows)
    every = [ms for row in rows for ms in [row['ms'], *row.get('ms_moved', [])]]
    if every:
        lines += ['', f'Median cold plan {statistics.median(every):.1f} ms over '
                  f'{len(every)} plans (a shared 2-core machine: compare runs side by side).']
    lines += ['', '## Cases that moved by more than 0.1 %', '',
              '| case | limits | J | ratios (' + ' ; '.join(sizes) + ') | seed | '
              'seeds moved (farthest) | warm |', '|---|---|---:|---|---|---|---|']
    for row in rows:
        if any(abs(x - 1) > WORSE for x in _all(row)):
            ratios = ' ; '.join(' / '.join(f'{x:.4f}' for x in row['ratios'][size])
                                for size in sizes)
            far = max(sizes, key=lambda size: max(abs(x - 1) for x in row['ratios'][size]))
            i = max(range(SEEDS), key=lambda i: abs(row['ratios'][far][i] - 1))
            warm = 'warm' if row['warm'] else 'cold'
            lines.append(f'| {row["case"]} | {row["limits"]} | {row["J"]:.2f} | {ratios} | '
                         f'{row["seed"]} | {row["seeds_moved"][far][i]} ({far} m) | {warm} |')
    if against:
        lines += arithmetic_table(against, rows)
    return '\n'.join(lines) + '\n'


def loop_table(rows: list[dict]) -> list[str]:
    """Lines on every moved field replanned warm from the unmoved plan (a node's loop)."""
    if not any('loop_ratios' in row for row in rows):
        return []
    lines = ['', '## Replans in a loop: every moved field, warm from the unmoved plan', '',
             'As the node replans: each moved field above planned with `warm_start` = the '
             'plan as given; ratio = J(replan) / J(given), the same target.', '',
             '| limits | plans | warm | cases worse | plans up | least | largest | '
             'median ms |', '|---|---:|---:|---:|---:|---:|---:|---:|']
    for label in ('on', 'off'):
        mine = [row for row in rows if row['limits'] == label and 'loop_ratios' in row]
        if not mine:
            continue
        r = [x for row in mine for x in row['loop_ratios']]
        worse = sum(any(x > 1 + WORSE for x in row['loop_ratios']) for row in mine)
        lines.append(f'| {label} | {len(r)} | {sum(sum(row["loop_warm"]) for row in mine)} '
                     f'| {worse} | {sum(x > 1 + WORSE for x in r)} | {min(r):.4f} | '
                     f'{max(r):.4f} | '
                     f'{statistics.median(ms for row in mine for ms in row["loop_ms"]):.1f} |')
    return lines


def arithmetic_table(host: list[dict], other: list[dict]) -> list[str]:
    """Lines comparing each case's unmoved J on the host's and the other arithmetic."""
    mine = {(r['case'], r['limits']): r for r in host}
    pairs = [(mine[key], r) for r in other if (key := (r['case'], r['limits'])) in mine]
    if not pairs:
        return []
    ratio = [b['J'] / a['J'] for a, b in pairs]
    apart = [(a, b, x) for (a, b), x in zip(pairs, ratio) if abs(x - 1.0) > WORSE]
    same = sum(a['J'] == b['J'] for a, b in pairs)
    moved = [(x, y) for a, b in pairs for x, y in zip(_all(a), _all(b))]
    lines = ['', '## The unmoved plans on both arithmetics', '',
             f'{len(pairs)} cases: J bit for bit the same in {same}; more than {WORSE:g} '
             f'apart in {len(apart)}; other / host from {min(ratio):.4f} to '
             f'{max(ratio):.4f}. Moved plans: ratio bit for bit the same in '
             f'{sum(x == y for x, y in moved)} of {len(moved)}.' + _loop_same(pairs)]
    if apart:
        lines += ['', '| case | limits | J host | J other | other / host | seed host | '
                  'seed other |', '|---|---|---:|---:|---:|---|---|']
        lines += [f'| {a["case"]} | {a["limits"]} | {a["J"]:.3f} | {b["J"]:.3f} | {x:.4f} | '
                  f'{a["seed"]} | {b["seed"]} |' for a, b, x in apart]
    return lines


def _loop_same(pairs: list[tuple[dict, dict]]) -> str:
    """' Replans in a loop: ... of ...' where both sides measured them, else ''."""
    loop = [(x, y) for a, b in pairs if 'loop_ratios' in a and 'loop_ratios' in b
            for x, y in zip(a['loop_ratios'], b['loop_ratios'])]
    return (f' Replans in a loop: ratio bit for bit the same in '
            f'{sum(x == y for x, y in loop)} of {len(loop)}.' if loop else '')


def bundled_plans() -> dict:
    """Return {case: [J, feasible, seed]} of every bundled scenario, w and limits."""
    from threat_planner import load_scenario, plan, PlannerConfig
    from threat_planner.core.inputs.settings import NO_LIMITS
    out = {}
    for path in sorted((ROOT / 'test' / 'data').glob('*.yaml')):
        sc = load_scenario(path)
        for w in (0.2, 0.5, 0.8):
            for label, lim in (('on', {}), ('off', NO_LIMITS)):
                if path.stem == 'big300_0' and label == 'on':
                    continue
                r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w, **lim),
                         airspace=sc.airspace if sc.airspace else None)
                out[f'{path.stem}@{w} {label}'] = [r.cost.J, bool(r.feasible), r.seed]
    return out


def quality_markdown(before: dict, after: dict, trees: tuple[str, str]) -> str:
    """Render perturbation_quality.md: J of every bundled plan before and after."""
    keys = [k for k in before if k in after]
    ratio = {k: after[k][0] / before[k][0] for k in keys}
    higher = [k for k in keys if ratio[k] > 1 + QUALITY_SLACK]
    lower = [k for k in keys if ratio[k] < 1 - QUALITY_SLACK]
    same = sum(after[k][0] == before[k][0] for k in keys)
    lines = ['# Quality gate of issue 28: every bundled plan before and after', '',
             f'Written by `python -m bench perturbation --quality` on '
             f'{time.strftime("%Y-%m-%d")}: before = `{trees[0]}`, after = `{trees[1]}`. '
             'Every `test/data/*.yaml` scenario at w 0.2 / 0.5 / 0.8, flight limits on (the '
             'defaults) and off (`big300_0` off only), cold plans of `best`, each J the '
             "checkout's own exact J of its own path.", '',
             f'* plans: {len(keys)}; higher than before by more than {QUALITY_SLACK:g} '
             f'relative: {len(higher)}' + (f' ({", ".join(higher)})' if higher else '')
             + f'; lower: {len(lower)}; bit for bit the same J: {same}',
             f'* largest rise {max(ratio.values()) - 1:.2e}, largest fall '
             f'{1 - min(ratio.values()):.2e} relative', '',
             '| case | limits | J before | J after | after / before | feasible | seed after |',
             '|---|---|---:|---:|---:|---|---|']
    for k in keys:
        case, label = k.rsplit(' ', 1)
        lines.append(f'| {case} | {label} | {before[k][0]:.6f} | {after[k][0]:.6f} | '
                     f'{ratio[k]:.7f} | {before[k][1]} / {after[k][1]} | {after[k][2]} |')
    return '\n'.join(lines) + '\n'


def _child(argv: list[str], flag: str, env: dict | None = None):
    """Run this suite in a child with ``argv``; return what it wrote through ``flag``."""
    import os
    import subprocess
    import tempfile
    with tempfile.TemporaryDirectory() as work:
        path = Path(work) / 'out.json'
        subprocess.run([sys.executable, '-m', 'bench', 'perturbation', *argv, flag, str(path)],
                       check=True, cwd=ROOT, env={**os.environ, **(env or {})})
        return json.loads(path.read_text())


def _quality(base: Path, out: Path) -> None:
    """Plan the bundled scenarios with `base` and with this checkout; write the table."""
    found = [_child(['--tree', str(tree)], '--bundled-json') for tree in (base.resolve(), ROOT)]
    out.write_text(quality_markdown(*found, (short_commit(base), short_commit(ROOT))))
    print(f'wrote {out}')


def main(argv: list[str] | None = None) -> None:
    """Run the cases and write the report (and the rows as JSON)."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--out', type=Path, default=None,
                    help=f'default {OUT} ({QUALITY_OUT} with --quality)')
    ap.add_argument('--json', type=Path, default=None, help='also write the rows here')
    ap.add_argument('--limits', nargs='+', choices=('on', 'off'), default=['on'])
    ap.add_argument('--tree', type=Path, default=None,
                    help="plan with this checkout's threat_planner")
    ap.add_argument('--quality', type=Path, default=None, metavar='BASE',
                    help='the quality gate instead: bundled plans of BASE and of this checkout')
    ap.add_argument('--arithmetic', choices=('host', 'other'), default='host',
                    help="'other': plan under OTHER_ARITHMETIC in a child process")
    ap.add_argument('--against', type=Path, default=None, metavar='ROWS',
                    help="the host's rows (--json of a host run): each unmoved J on both")
    ap.add_argument('--bundled-json', type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument('--rows-json', type=Path, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.quality is not None:
        return _quality(args.quality, args.out or QUALITY_OUT)
    tree = (args.tree or ROOT).resolve()
    if args.tree is not None:
        sys.path.insert(0, str(tree))
    if args.bundled_json is not None:
        args.bundled_json.write_text(json.dumps(bundled_plans()))
        return None
    if args.rows_json is not None:
        args.rows_json.write_text(json.dumps(run(tuple(args.limits))))
        return None
    other = args.arithmetic == 'other'
    args.out = args.out or (OTHER_OUT if other else OUT)
    limits = ['--limits', *args.limits] + (['--tree', str(tree)] if args.tree else [])
    rows = (_child(limits, '--rows-json', OTHER_ARITHMETIC) if other
            else run(tuple(args.limits)))
    against = json.loads(args.against.read_text()) if args.against else None
    args.out.write_text(markdown(rows, short_commit(tree), args.arithmetic, against))
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    print(f'wrote {args.out}')
