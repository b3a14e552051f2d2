"""Fresh random fields every run: HEAD beside a baseline and the yardsticks, and the gate.

Usage (from the root of the checkout to measure: HEAD is its working tree)::

    .venv/bin/python -m bench fresh --quick                  # smoke run, a few minutes
    .venv/bin/python -m bench fresh --fields-per-cell 2 --gate --keep-regressions
    .venv/bin/python -m bench fresh --seed S --only uniform-n10000-f1-w0.5-on

The seed comes from the clock (first line of the output; ``--seed`` replays it). Each
field is :func:`bench.toolkit.fresh_fields.make_field` of a family, a size and an index
(``--fields-per-cell`` per size and family), planned at every ``--ws`` with the limits on
(PlannerConfig's defaults, given to both checkouts explicitly) and off (``LIMITS_OFF``).
One long-lived worker process per checkout (:class:`bench.toolkit.fresh_runs.Worker`)
plans, the two taking turns case by case (who goes first alternates), each after
untimed plans at 20 and 2,500 threats. This process recomputes J of both paths with
HEAD's closed form and checks the end points, the box and the limits with the bench's
own check (:func:`bench.toolkit.fresh_runs.grade`); each checkout's own J and flag are
kept beside. Then the yardsticks, in ``--jobs`` processes, one job a field: the in-box one
(:func:`bench.toolkit.yardstick.in_box_yardstick`, a 41^3 grid up to 100 threats, 31^3
above) on limits-off cases up to ``--inbox-max`` threats, and the limited one
(:func:`bench.toolkit.yardstick.limited_yardstick`, SLSQP at the planner's 40 segments as
issue 42 ran it, from the in-box candidates, the straight line and HEAD's limit-free plan
of the same field and w) on limits-on cases up to ``--limited-max``. Nothing is cached.
Writes ``--out`` (Markdown) and a ``.json`` beside it with every case.
"""

from __future__ import annotations

import argparse
from concurrent.futures import as_completed, ProcessPoolExecutor
import json
import multiprocessing
import os
from pathlib import Path
import re
import sys
import time

import numpy as np

from bench.toolkit import fresh_report as fr
from bench.toolkit.cases import LIMITS_OFF, WS
from bench.toolkit.fresh_fields import FAMILIES, make_field
from bench.toolkit.fresh_runs import baseline_tree, grade, newest_tag, tree_state, Worker
from bench.toolkit.repo import DATA, machine, RESULTS, ROOT

SIZES = (20, 100, 300, 1000, 3000, 10000)
QUICK = {'sizes': (20, 100, 300), 'ws': (0.5,), 'fields_per_cell': 1}
REGRESSIONS = DATA / 'fresh_regressions'
#: Fields from this size on keep their threats in a .npy beside the regression YAML.
NPY_FROM = 1000
_ID = re.compile(r'^(?P<family>[a-z]+)-n(?P<n>\d+)-f(?P<k>\d+)-w(?P<w>[0-9.]+)-(?P<lim>on|off)$')


def case_id(family: str, n: int, k: int, w: float, limits: str) -> str:
    """Return the case's name, which ``--only`` takes back."""
    return f'{family}-n{n}-f{k}-w{w:g}-{limits}'


def parse_id(text: str) -> dict:
    """Return ``family``, ``n``, ``k``, ``w`` and ``limits`` of a case name."""
    m = _ID.match(text)
    if not m or m['family'] not in FAMILIES:
        raise ValueError(f'--only {text}: not a case name like uniform-n300-f0-w0.5-on')
    return {'family': m['family'], 'n': int(m['n']), 'k': int(m['k']), 'w': float(m['w']),
            'limits': m['lim']}


def cases(sizes, families, fields_per_cell: int, ws) -> list[dict]:
    """Every case in run order: by size, family and field, then w, limits off then on."""
    return [{'family': f, 'n': n, 'k': k, 'w': w, 'limits': lim}
            for n in sizes for f in families for k in range(fields_per_cell)
            for w in ws for lim in ('off', 'on')]


def on_limits() -> dict:
    """Return PlannerConfig's default limits (this checkout's), the 'limits on' rules."""
    from threat_planner import PlannerConfig
    cfg = PlannerConfig()
    return {k: getattr(cfg, k) for k in LIMITS_OFF}


def grid_for(n: int) -> int:
    """Grid nodes per axis of the in-box yardstick: 41 up to 100 threats, 31 above."""
    return 41 if n <= 100 else 31


def yardstick_job(job: dict) -> dict:
    """Both yardsticks of one field at the w values asked; ``{w: {'in_box', 'limited'}}``.

    One grid for every w (it depends on the field alone); the limited yardstick starts from
    the in-box candidates of its w, the straight line and ``job['extra'][w]`` if given.
    """
    from bench.toolkit.grid import build_grid
    from bench.toolkit.yardstick import in_box_yardstick, limited_yardstick
    field = make_field(job['family'], job['n'], job['seed'], job['k'])
    threats, s, t, box = field.problem()
    graph = build_grid(threats, s, t, box, n=job['grid'])
    out = {}
    for w in job['ws']:
        inb = in_box_yardstick(threats, s, t, box, w, graph=graph)
        res = {'in_box': {'J': inb['J'], 'seconds': inb['seconds'], 'how': inb['how'],
                          'grid': job['grid']}}
        if w in job['limited']:
            extra = job['extra'].get(w)
            lim = limited_yardstick(threats, s, t, box, w, **job['limits'],
                                    n_segments=job['segments'], in_box=inb,
                                    extra_starts=[] if extra is None else
                                    [('HEAD limit-free plan', np.array(extra))])
            res['limited'] = {'J': lim['J'], 'seconds': lim['seconds'], 'how': lim['how'],
                              'starts': lim['starts']}
        out[w] = res
    return out


def _entry(own: dict, field, w: float, limits: dict) -> dict:
    """Return a checkout's cell: the grading of its path beside its own figures."""
    graded = grade(own.get('path'), field, w, limits)
    cell = {**graded, 'ms': own['ms']}
    if 'error' in own:
        cell['error'] = own['error']
    else:
        cell.update(own_J=own['J'], own_feasible=own['feasible'])
    return cell


def run_plans(todo: list[dict], seed: int, head: Worker, base: Worker, limits_on: dict
              ) -> tuple[list[dict], dict]:
    """Plan every case on both checkouts in turns; the rows and HEAD's limit-free paths.

    The paths are keyed ``(family, n, k, w)``; a limits-on case whose limit-free plan is
    not among the cases (``--only``) gets one from HEAD, untimed.
    """
    rows, free, turn = [], {}, 0
    for case in todo:
        field = make_field(case['family'], case['n'], seed, case['k'])
        key = (case['family'], case['n'], case['k'], case['w'])
        limits = limits_on if case['limits'] == 'on' else LIMITS_OFF
        pair = [('base', base), ('head', head)]
        plans = {label: worker.plan(field, case['w'], limits)
                 for label, worker in (pair if turn % 2 == 0 else pair[::-1])}
        turn += 1
        if case['limits'] == 'off':
            free[key] = plans['head'].get('path')
        elif key not in free:
            free[key] = head.plan(field, case['w'], LIMITS_OFF).get('path')
        row = {'id': case_id(**case), **case,
               'head': _entry(plans['head'], field, case['w'], limits),
               'base': _entry(plans['base'], field, case['w'], limits),
               'in_box': None, 'limited': None}
        rows.append(row)
        r = fr.ratio(row, 'base')
        print(f"{row['id']}: base J {row['base']['J']:.4f} ({row['base']['ms']:.0f} ms), "
              f"HEAD J {row['head']['J']:.4f} ({row['head']['ms']:.0f} ms), HEAD/base "
              f"{'-' if r is None else f'{r:.5f}'}"
              + ('' if row['head']['feasible'] else f" HEAD infeasible: {row['head']['why']}"),
              flush=True)
    return rows, free


def run_yardsticks(rows: list[dict], free: dict, args: argparse.Namespace,
                   limits_on: dict) -> None:
    """Fill in each row's ``in_box`` and ``limited`` where its size asks for them."""
    jobs: dict[tuple, dict] = {}
    for row in rows:
        on = row['limits'] == 'on'
        if (on and row['n'] > args.limited_max) or (not on and row['n'] > args.inbox_max):
            continue
        key = (row['family'], row['n'], row['k'])
        job = jobs.setdefault(key, {'family': row['family'], 'n': row['n'], 'k': row['k'],
                                    'seed': args.seed, 'grid': args.grid or grid_for(row['n']),
                                    'ws': [], 'limited': [], 'extra': {},
                                    'limits': limits_on, 'segments': args.limited_segments})
        if row['w'] not in job['ws']:
            job['ws'].append(row['w'])
        if on:
            job['limited'].append(row['w'])
            job['extra'][row['w']] = free.get(key + (row['w'],))
    if not jobs:
        return
    by_key = {(r['family'], r['n'], r['k'], r['w'], r['limits']): r for r in rows}
    print(f'yardsticks: {len(jobs)} fields in {args.jobs} processes', flush=True)
    # One BLAS thread a process: the pool already fills the cores.
    saved = {k: os.environ.get(k) for k in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS')}
    os.environ.update(dict.fromkeys(saved, '1'))
    try:
        with ProcessPoolExecutor(max(args.jobs, 1),
                                 mp_context=multiprocessing.get_context('spawn')) as pool:
            futures = {pool.submit(yardstick_job, job): key for key, job in jobs.items()}
            for done in as_completed(futures):
                key = futures[done]
                for w, res in done.result().items():
                    if (off := by_key.get(key + (w, 'off'))) and off['n'] <= args.inbox_max:
                        off['in_box'] = res['in_box']
                    if (on := by_key.get(key + (w, 'on'))) and 'limited' in res:
                        on['limited'] = res['limited']
                print(f'yardsticks of {key[0]}-n{key[1]}-f{key[2]} done', flush=True)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def keep_regressions(rows: list[dict], seed: int, head: str, base: str) -> list[Path]:
    """Write every case above the baseline by more than the gate's factor as a scenario."""
    from threat_planner.core.inputs.scenario import save_scenario, Scenario
    written = []
    for row in rows:
        r = fr.ratio(row, 'base')
        if r is None or r <= fr.BASE_MAX:
            continue
        field = make_field(row['family'], row['n'], seed, row['k'])
        threats, s, t, box = field.problem()
        stem = f"fresh_s{seed}_{row['family']}_n{row['n']}_f{row['k']}"
        name = f"{stem}_w{row['w']:g}_{row['limits']}".replace('.', 'p')
        text = (f"python -m bench fresh --seed {seed} --only {row['id']}: w {row['w']:g}, "
                f"limits {row['limits']}; HEAD {head} J {row['head']['J']:.6g} against "
                f"baseline {base} J {row['base']['J']:.6g} (x{r:.4f})")
        REGRESSIONS.mkdir(parents=True, exist_ok=True)
        path = REGRESSIONS / f'{name}.yaml'
        save_scenario(Scenario(name=name, frame_id='map', description=text, box=box,
                               start=s, goal=t, threats=threats), path,
                      # One table a field: its cases at other w and limits share it.
                      threats_file=f'{stem}.npy' if row['n'] >= NPY_FROM else None)
        written.append(path)
    return written


def _args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seed', type=int, help='replay this seed (default: from the clock)')
    ap.add_argument('--baseline', help='git revision to compare with (default: newest tag)')
    ap.add_argument('--sizes', type=int, nargs='+', default=SIZES)
    ap.add_argument('--families', nargs='+', choices=list(FAMILIES), default=list(FAMILIES))
    ap.add_argument('--ws', type=float, nargs='+', default=WS)
    ap.add_argument('--fields-per-cell', type=int, default=2,
                    help='fields per size and family (default 2: 360 cases)')
    ap.add_argument('--limited-max', type=int, default=300,
                    help='largest size for the limited yardstick (default 300)')
    ap.add_argument('--inbox-max', type=int, default=1000,
                    help='largest size for the in-box yardstick (default 1000; about 3 min '
                         'a 1,000-threat field)')
    ap.add_argument('--limited-segments', type=int, default=40,
                    help="the limited yardstick's segments (default 40, the planner's)")
    ap.add_argument('--grid', type=int, help='in-box grid nodes per axis (default 41, 31 '
                                             'above 100 threats)')
    ap.add_argument('--jobs', type=int, default=2, help='yardstick processes (default 2)')
    ap.add_argument('--only', help='plan just this case (a name from a report)')
    ap.add_argument('--quick', action='store_true',
                    help='sizes 20 100 300, one field per cell, w 0.5')
    ap.add_argument('--out', type=Path, help='Markdown report (default bench/results/'
                    'fresh.md; /tmp/fresh_quick.md with --quick, /tmp/fresh_only.md with '
                    '--only); a .json beside it')
    ap.add_argument('--keep-regressions', action='store_true',
                    help='write cases above the baseline by > 1.001 into '
                         'test/data/fresh_regressions/')
    ap.add_argument('--gate', action='store_true', help='exit 1 if the gate fails')
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.ws, args.fields_per_cell = (QUICK['sizes'], QUICK['ws'],
                                                     QUICK['fields_per_cell'])
    if args.out is None:
        args.out = (Path('/tmp/fresh_only.md') if args.only else
                    Path('/tmp/fresh_quick.md') if args.quick else RESULTS / 'fresh.md')
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the suite; 1 with ``--gate`` when the gate fails, 2 without a baseline."""
    args = _args(argv)
    args.seed = int(time.time()) if args.seed is None else args.seed
    print(f'fresh: seed {args.seed} (replay: python -m bench fresh --seed {args.seed})',
          flush=True)
    t0 = time.time()
    rev = args.baseline or newest_tag(ROOT)
    if not rev:
        print('fresh: no release tag to compare with: give --baseline REV', file=sys.stderr)
        return 2
    try:
        tree, commit = baseline_tree(ROOT, rev)
    except ValueError as exc:
        print(f'fresh: {exc}', file=sys.stderr)
        return 2
    todo = ([parse_id(args.only)] if args.only else
            cases(args.sizes, args.families, args.fields_per_cell, args.ws))
    head_state, base_state = tree_state(ROOT), f'{rev} = {commit[:7]}'
    print(f'fresh: HEAD {ROOT} ({head_state}) against {base_state} ({tree}): '
          f'{len(todo)} cases', flush=True)
    limits_on = on_limits()
    head, base = Worker(ROOT), Worker(tree)
    for n in (20, 2500):   # compiled kernels and the big-field loader, untimed
        for worker in (base, head):
            worker.plan(make_field('uniform', n, 0), 0.5, limits_on)
    try:
        rows, free = run_plans(todo, args.seed, head, base, limits_on)
    finally:
        head.close()
        base.close()
    plans_s = time.time() - t0
    run_yardsticks(rows, free, args, limits_on)
    kept = keep_regressions(rows, args.seed, head_state, base_state) \
        if args.keep_regressions else []
    gate = fr.gate(rows)
    wall = time.time() - t0
    write(args, rows, gate, kept, {'head': head_state, 'baseline': base_state,
                                   'baseline_tree': str(tree), 'wall_s': wall,
                                   'plans_s': plans_s, 'limits_on': limits_on})
    for ok, text in gate:
        print(('  ' if ok else '! ') + text)
    print(f'fresh: {len(rows)} cases in {wall / 60:.1f} min; wrote {args.out}')
    return 1 if args.gate and not all(ok for ok, _ in gate) else 0


def write(args: argparse.Namespace, rows: list[dict], gate: list, kept: list[Path],
          info: dict) -> None:
    """Write the Markdown report and the JSON of every case."""
    replay = f'python -m bench fresh --seed {args.seed}'
    opts = (f"sizes {' '.join(map(str, args.sizes))}; families {', '.join(args.families)}; "
            f"w {' '.join(f'{w:g}' for w in args.ws)}; {args.fields_per_cell} field(s) per "
            f'size and family; limits on ({info["limits_on"]}) and off')
    if args.only:
        opts, replay = f'one case: {args.only}', f'{replay} --only {args.only}'
    lines = [
        '# Fresh fields: HEAD, the baseline and the yardsticks', '',
        f'Written by `python -m bench fresh` on {time.strftime("%Y-%m-%d %H:%M")}, seed '
        f'**{args.seed}** (replay: `{replay}` with the same options): HEAD = '
        f'`{info["head"]}` (the working tree), baseline = `{info["baseline"]}`; {opts}. '
        f'{len(rows)} cases in {info["wall_s"] / 60:.1f} min (plans '
        f'{info["plans_s"] / 60:.1f} min, then the yardsticks in {args.jobs} processes) on '
        f'{machine()}, shared with other jobs: read the time ratios, the two checkouts took '
        'turns. Every J is HEAD\'s closed form of the path, every "infeasible" the bench\'s '
        'own check (end points, box, limits); the in-box yardstick ran on limits-off cases '
        f'up to {args.inbox_max} threats, the limited one on limits-on cases up to '
        f'{args.limited_max} at {args.limited_segments} segments. Fields: '
        '`bench/toolkit/fresh_fields.py`.', '',
        '## Gate (issue 42, item 2)', '']
    lines += [f'* {text}' for _, text in gate]
    lines += ['', f"Overall: {'PASS' if all(ok for ok, _ in gate) else 'FAIL'}.", '',
              '## Per size and family', '', *fr.tables(rows), '',
              '## Worst 10 cases', '', *fr.worst_cases(rows, args.seed), '',
              '## Own figures against the independent ones', '', *fr.self_grading(rows)]
    if kept:
        lines += ['', f'Regression scenarios written ({len(kept)}): '
                  + ', '.join(f'`{p.relative_to(ROOT)}`' for p in kept)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text('\n'.join(lines) + '\n')
    data = {'seed': args.seed, 'command': ' '.join(['python -m bench fresh', *sys.argv[1:]]),
            **info, 'gate': [{'pass': ok, 'line': text} for ok, text in gate],
            'cases': rows}
    args.out.with_suffix('.json').write_text(
        json.dumps(data, indent=1, default=lambda o: None if o is None else str(o),
                   allow_nan=True) + '\n')
