"""The speed targets of issue 42 item 4, on fresh fields, as ratios measured in one run.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python -m bench large_fields                  # ~6 min
    .venv/bin/python -m bench large_fields --seed S --baseline REV --fields 3

Rows, each a fresh process, taking turns so that a shared machine's load hits all alike:

* **10,000 threats, default limits**: fresh uniform fields (the issue's recipe:
  :func:`bench.toolkit.fresh_fields.uniform`), new every seed. In one process: a bare
  ``scipy.spatial.Delaunay`` of the points, then ``plan()`` once (kernels loaded, caches
  filled) and ``--repeats`` more, warm; HEAD and ``--baseline`` alike. Targets: warm
  ``plan()`` <= 0.6 s; and ``threat-planner plan`` on the field as a ``threats_file: .npy``
  scenario, a fresh process, wall <= 6x the Delaunay (HEAD).
* **20 threats**: the bundled 20-threat cases (:data:`bench.toolkit.cases.SCENARIOS` x
  w 0.2 / 0.5 / 0.8), default limits, warm ``plan()`` median of ``--repeats`` per case.
  Target: the median over the cases <= 7 ms; the baseline's beside it.
* **100,000 threats**: one fresh uniform field through ``threat-planner plan`` as a
  ``threats_file: .npy`` scenario (peak RSS of the child from ``wait4``), and in another
  process ``plan()`` under cProfile beside a bare Delaunay of the same points. Targets:
  feasible, ``plan()`` <= 8x the Delaunay, peak RSS <= 4 GiB. The profile goes to
  ``bench/results/profile_100k.txt``.

Writes ``bench/results/large_fields.{md,json}``.
"""

from __future__ import annotations

import argparse
import compileall
import datetime as dt
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

from bench.suites.cli_scale import run_cli
from bench.toolkit.checkouts import THEN_BENCH
from bench.toolkit.fresh_runs import baseline_tree, newest_tag
from bench.toolkit.repo import command, machine, RESULTS, ROOT

TARGETS = {'10000 warm plan() ms': 600.0, '10000 CLI / Delaunay': 6.0,
           '20 warm median ms': 7.0, '100000 plan() / Delaunay': 8.0,
           '100000 peak RSS MiB': 4096.0}


def child(spec: str) -> None:
    """In a fresh process of one checkout: measure as ``spec`` (JSON) says; print JSON."""
    from scipy.spatial import Delaunay
    from threat_planner import plan, PlannerConfig
    args = json.loads(spec)
    out: dict = {}
    if args['kind'] == 'field':
        from bench.toolkit.fresh_fields import make_field
        field = make_field('uniform', args['n'], args['seed'], args['k'])
        t0 = time.perf_counter()
        Delaunay(field.positions)
        out['delaunay_ms'] = 1e3 * (time.perf_counter() - t0)
        threats, s, t, box = field.problem()
        cfg = PlannerConfig(w=0.5)
        prof = None
        if args.get('profile'):
            import cProfile
            prof = cProfile.Profile()
        times = []
        for i in range(args['repeats'] + (0 if prof else 1)):
            if prof:
                prof.enable()
            t0 = time.perf_counter()
            result = plan(threats, s, t, box, cfg)
            times.append(1e3 * (time.perf_counter() - t0))
            if prof:
                prof.disable()
        out['plan_ms'] = times if prof else times[1:]
        out['J'] = float(result.cost.J)
        out['feasible'] = bool(result.limit_check is None or result.limit_check.feasible)
        out['stages_ms'] = {k: round(v, 1) for k, v in result.timings_ms.items()}
        if prof:
            import io
            import pstats
            text = io.StringIO()
            stats = pstats.Stats(prof, stream=text)
            stats.sort_stats('cumulative').print_stats(30)
            stats.sort_stats('tottime').print_stats(25)
            out['profile'] = text.getvalue()
    else:
        from bench.toolkit.cases import SCENARIOS, WS
        from bench.toolkit.repo import DATA
        from threat_planner import load_scenario
        medians = []
        for name in SCENARIOS:
            sc = load_scenario(DATA / f'{name}.yaml')
            for w in WS:
                cfg = PlannerConfig(w=w)
                plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
                runs = []
                for _ in range(args['repeats']):
                    t0 = time.perf_counter()
                    plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
                    runs.append(1e3 * (time.perf_counter() - t0))
                medians.append(statistics.median(runs))
        out['case_ms'] = medians
    print(json.dumps(out))


def _in(tree: Path, spec: dict) -> dict:
    """Run :func:`child` in a fresh process of checkout ``tree``."""
    code = THEN_BENCH + 'from bench.suites.large_fields import child\nchild(sys.argv[1])\n'
    env = {k: v for k, v in os.environ.items() if k != 'PYTHONPATH'}
    done = subprocess.run([sys.executable, '-c', code, json.dumps(spec)], cwd=tree, env=env,
                          capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f'{tree}: {done.stderr.strip()[-400:]}')
    return json.loads(done.stdout.strip().splitlines()[-1])


def npy_scenario(n: int, seed: int, k: int, folder: Path) -> Path:
    """Write the fresh uniform field as a scenario with a ``threats_file: .npy``."""
    import numpy as np
    import yaml
    from bench.toolkit.fresh_fields import make_field
    field = make_field('uniform', n, seed, k)
    np.save(folder / f'threats_{n}_{k}.npy',
            np.column_stack([field.positions, field.intensities]))
    path = folder / f'field_{n}_{k}.yaml'
    path.write_text(yaml.safe_dump({
        'bounds': {'min': field.lo.tolist(), 'max': field.hi.tolist()},
        'start': field.start.tolist(), 'goal': field.goal.tolist(),
        'threats_file': f'threats_{n}_{k}.npy'}))
    return path


def measure(args: argparse.Namespace, trees: list[tuple[str, Path]]) -> dict:
    """Every row, the checkouts taking turns; the raw measurements."""
    raw: dict = {'10000': {label: [] for label, _ in trees}, '10000 cli': [],
                 '20': {label: [] for label, _ in trees}}
    with tempfile.TemporaryDirectory(prefix='large_fields_') as tmp:
        for k in range(args.fields):
            path = npy_scenario(10_000, args.seed, k, Path(tmp))
            for label, tree in trees:
                raw['10000'][label].append(_in(tree, {'kind': 'field', 'n': 10_000,
                                                      'seed': args.seed, 'k': k,
                                                      'repeats': args.repeats}))
            row = run_cli(path, [])
            # The Delaunay of this field in this process, right after the command.
            row['delaunay_ms'] = raw['10000'][trees[0][0]][-1]['delaunay_ms']
            raw['10000 cli'].append(row)
        for _ in range(2):
            for label, tree in trees:
                raw['20'][label].append(_in(tree, {'kind': 'small', 'repeats': args.repeats}))
        if not args.no_100k:
            path = npy_scenario(100_000, args.seed, 0, Path(tmp))
            raw['100000 cli'] = run_cli(path, ['--json', str(Path(tmp) / 'plan100k.json')])
            raw['100000 cli']['feasible'] = _feasible(Path(tmp) / 'plan100k.json')
            raw['100000'] = _in(ROOT, {'kind': 'field', 'n': 100_000, 'seed': args.seed,
                                       'k': 0, 'repeats': 1, 'profile': True})
    return raw


def _feasible(path: Path) -> bool:
    """The ``feasible`` of a ``--json`` plan file (end points, box and limits met)."""
    return bool(json.loads(path.read_text())['feasible'])


def summary(raw: dict, labels: list[str]) -> dict:
    """Medians, ratios and the verdicts."""
    med = statistics.median
    out: dict = {'10000': {}, '20': {}}
    for label in labels:
        runs = raw['10000'][label]
        out['10000'][label] = {
            'plan_ms': med(med(r['plan_ms']) for r in runs),
            'worst_field_ms': max(med(r['plan_ms']) for r in runs),
            'delaunay_ms': med(r['delaunay_ms'] for r in runs),
            'ratio': med(med(r['plan_ms']) / r['delaunay_ms'] for r in runs),
            'J': [r['J'] for r in runs], 'feasible': all(r['feasible'] for r in runs),
            'stages_ms': runs[0]['stages_ms']}
        cases = [med(c) for c in zip(*(r['case_ms'] for r in raw['20'][label]))]
        out['20'][label] = {'median_ms': med(cases), 'worst_ms': max(cases)}
    cli = raw['10000 cli']
    out['10000 cli'] = {'wall_ms': med(r['wall_ms'] for r in cli),
                        'ratio': med(r['wall_ms'] / r['delaunay_ms'] for r in cli),
                        'worst_ratio': max(r['wall_ms'] / r['delaunay_ms'] for r in cli),
                        'peak_rss_mib': max(r['peak_rss_mib'] for r in cli)}
    head = labels[0]
    verdicts = {'10000 warm plan() ms': out['10000'][head]['plan_ms'],
                '10000 CLI / Delaunay': out['10000 cli']['ratio'],
                '20 warm median ms': out['20'][head]['median_ms']}
    if '100000' in raw:
        big = raw['100000']
        out['100000'] = {'plan_ms': big['plan_ms'][0], 'delaunay_ms': big['delaunay_ms'],
                         'ratio': big['plan_ms'][0] / big['delaunay_ms'], 'J': big['J'],
                         'feasible': big['feasible'], 'stages_ms': big['stages_ms'],
                         'cli': {k: raw['100000 cli'][k] for k in
                                 ('wall_ms', 'plan_ms', 'peak_rss_mib', 'J', 'feasible')}}
        # The verdict is the CLI's plan() (its first in the process, as a user runs it).
        out['100000']['cli_ratio'] = raw['100000 cli']['plan_ms'] / big['delaunay_ms']
        verdicts['100000 plan() / Delaunay'] = out['100000']['cli_ratio']
        verdicts['100000 peak RSS MiB'] = out['100000']['cli']['peak_rss_mib']
    out['verdicts'] = {k: {'value': v, 'target': TARGETS[k], 'met': v <= TARGETS[k]}
                       for k, v in verdicts.items()}
    return out


def markdown(s: dict, meta: dict, labels: list[str]) -> str:
    """Return the report."""
    lines = ['# Speed on large and small fields (issue 42 item 4)', '',
             f"Written by `{meta['command']}` on {meta['date']}, seed **{meta['seed']}**; "
             f"{meta['machine']}, shared with other jobs (load {meta['load']}): read the "
             f"ratios, measured in one run. Checkouts: {meta['trees']}. Fresh uniform fields "
             '(`bench/toolkit/fresh_fields.py`), w 0.5, default limits; every row a fresh '
             f"process; {meta['fields']} field(s) of 10,000 threats, warm `plan()` = median "
             f"of {meta['repeats']} after one plan in the process.", '',
             '| row | ' + ' | '.join(labels) + ' |', '|---|' + '---:|' * len(labels)]

    def row(name, key, sub, fmt):
        cells = ' | '.join(format(s[key][lb][sub], fmt) for lb in labels)
        lines.append(f'| {name} | {cells} |')
    row('10,000: warm plan() ms (median over fields)', '10000', 'plan_ms', '.0f')
    row('10,000: slowest field ms', '10000', 'worst_field_ms', '.0f')
    row('10,000: Delaunay ms (same process)', '10000', 'delaunay_ms', '.0f')
    row('10,000: plan() / Delaunay', '10000', 'ratio', '.2f')
    row('20 threats: warm plan() median ms over the cases', '20', 'median_ms', '.1f')
    row('20 threats: slowest case ms', '20', 'worst_ms', '.1f')
    lines.append('| 10,000: J per field | ' + ' | '.join(
        ', '.join(f'{j:.3f}' for j in s['10000'][lb]['J']) for lb in labels) + ' |')
    lines += ['', f"HEAD's stages on the first 10,000-threat field [ms]: "
              f"{s['10000'][labels[0]]['stages_ms']}.", '',
              f"`threat-planner plan` on the 10,000-threat fields (HEAD, `threats_file: .npy`, "
              f"fresh process): wall {s['10000 cli']['wall_ms']:.0f} ms median, "
              f"{s['10000 cli']['ratio']:.2f}x the Delaunay (worst field "
              f"{s['10000 cli']['worst_ratio']:.2f}x), peak RSS "
              f"{s['10000 cli']['peak_rss_mib']:.0f} MiB.", '']
    if '100000' in s:
        b = s['100000']
        lines += [f"100,000 threats (HEAD): `plan()` {b['plan_ms']:.0f} ms under cProfile, "
                  f"Delaunay {b['delaunay_ms']:.0f} ms, ratio {b['ratio']:.2f}; J "
                  f"{b['J']:.3f}, feasible {b['feasible']}; stages {b['stages_ms']}. "
                  f"Through the CLI: wall {b['cli']['wall_ms']:.0f} ms, plan "
                  f"{b['cli']['plan_ms']:.0f} ms ({b['cli_ratio']:.2f}x the Delaunay: the "
                  f"verdict), peak RSS {b['cli']['peak_rss_mib']:.0f} MiB, "
                  f"J {b['cli']['J']:.3f}, feasible {b['cli']['feasible']}. Profile: "
                  '`bench/results/profile_100k.txt`.', '']
    lines += ['| target | value | verdict |', '|---|---:|---|']
    for name, v in s['verdicts'].items():
        lines.append(f"| {name} <= {v['target']:g} | {v['value']:.2f} | "
                     f"**{'met' if v['met'] else 'MISSED'}** |")
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Measure, write the report and the profile; return the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seed', type=int, help='replay this seed (default: from the clock)')
    ap.add_argument('--baseline', help='git revision beside HEAD (default: newest tag, if any)')
    ap.add_argument('--fields', type=int, default=3, help='10,000-threat fields (default 3)')
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--no-100k', action='store_true', help='leave out the 100,000 threats')
    ap.add_argument('--out', type=Path, default=RESULTS / 'large_fields.md')
    args = ap.parse_args(argv)
    args.seed = args.seed if args.seed is not None else int(time.time()) % 2**31
    print(f'large_fields: seed {args.seed}', flush=True)
    trees = [('HEAD', ROOT)]
    rev = args.baseline or newest_tag(ROOT)
    if rev:
        trees.append((f'base {rev}', baseline_tree(ROOT, rev)[0]))
    compileall.compile_dir(str(ROOT / 'threat_planner'), quiet=1)
    raw = measure(args, trees)
    labels = [label for label, _ in trees]
    s = summary(raw, labels)
    from bench.toolkit.checkouts import describe
    meta = {'command': command('large_fields', sys.argv[1:] if argv is None else argv),
            'date': dt.datetime.now().isoformat(timespec='minutes'), 'seed': args.seed,
            'machine': machine(), 'load': ', '.join(f'{x:.1f}' for x in os.getloadavg()),
            'trees': describe(trees), 'fields': args.fields, 'repeats': args.repeats}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if '100000' in raw:
        (args.out.parent / 'profile_100k.txt').write_text(
            f"# plan() on a fresh uniform 100,000-threat field (seed {args.seed}), w 0.5, "
            f"default limits, first plan in the process, at {describe(trees[:1])}\n"
            + raw['100000'].pop('profile'))
    args.out.with_suffix('.json').write_text(json.dumps({'meta': meta, 'summary': s,
                                                         'raw': raw}, indent=1))
    text = markdown(s, meta, labels)
    args.out.write_text(text)
    print(text)
    return 0
