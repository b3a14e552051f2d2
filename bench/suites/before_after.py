"""Cold plans of two checkouts side by side, interleaved case by case, in one run.

Usage (from the repository root)::

    git worktree add /tmp/base <commit>
    .venv/bin/python -m bench before_after /tmp/base [--out bench/results/before_after.md]
    .venv/bin/python -m bench before_after /tmp/base --airspace --repeats 3 \
        --out bench/results/before_after_airspace.md

One long-lived worker process per checkout (``PYTHONPATH`` = that checkout) plans the
bundled 20-threat scenarios at w = 0.2 / 0.5 / 0.8 with the default settings (the flight
limits on) and with the limits off, and 1,000 / 10,000 threats of
:func:`bench.toolkit.cases.scale_problem` at w 0.5; the two workers take turns on every case, after
one untimed plan each to load the compiled kernels, so machine load falls on both alike
(``--airspace``: the bundled airspace scenarios at w = 0.5 instead, limits on and off);
``--repeats`` turns per case (default 5; the plans are deterministic, so the runs differ
only by the machine's load), reported as the median and the least time of each. Every J
is the checkout's own exact J of its own path; the table gives both and their ratio, the
times and their ratios.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import time

from bench.toolkit.cases import LIMITS_OFF as OFF, SCENARIOS, WS
from bench.toolkit.checkouts import short_commit, THEN_BENCH
from bench.toolkit.repo import DATA, RESULTS, ROOT

WORKER = THEN_BENCH + r'''
import json, time
from threat_planner import load_scenario, plan, PlannerConfig
from bench.toolkit.cases import scale_problem
print(json.dumps({'ready': True, 'package': threat_planner.__file__}), flush=True)
for line in sys.stdin:
    case = json.loads(line)
    airspace = None
    if 'threats' in case:
        threats, s, t, box = scale_problem(case['threats'])
    else:
        sc = load_scenario(case['file'])
        threats, s, t, box, airspace = sc.threats, sc.start, sc.goal, sc.box, sc.airspace
    cfg = PlannerConfig(w=case['w'], **case['limits'])
    t0 = time.perf_counter()
    r = plan(threats, s, t, box, cfg, airspace=airspace)
    ms = 1e3 * (time.perf_counter() - t0)
    print(json.dumps({'ms': ms, 'J': r.cost.J, 'feasible': bool(r.feasible)}), flush=True)
'''


class Worker:
    """A planning process on one checkout."""

    def __init__(self, tree: Path) -> None:
        env = dict(os.environ, PYTHONPATH=str(tree))
        self.proc = subprocess.Popen([sys.executable, '-c', WORKER], env=env, text=True, cwd=tree,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self.package = json.loads(self.proc.stdout.readline())['package']
        assert self.package.startswith(str(tree.resolve())), (self.package, tree)

    def plan(self, case: dict) -> dict:
        """Plan one case in the worker; its ms, J and feasibility."""
        self.proc.stdin.write(json.dumps(case) + '\n')
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self) -> None:
        """End the worker (its input closed)."""
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def _summary(runs: list[dict]) -> dict:
    """One cell from its repeated plans: median and least ms, J and feasibility."""
    js = {r['J'] for r in runs}
    # Deterministic plans: a J that moved between repeats would be a bug worth seeing.
    assert len(js) == 1, f'J differs between repeats: {sorted(js)}'
    return {'ms': statistics.median(r['ms'] for r in runs), 'min': min(r['ms'] for r in runs),
            'J': runs[0]['J'], 'feasible': runs[0]['feasible']}


def cases(airspace: bool = False) -> list[dict]:
    """Every case, in run order (``airspace``: the airspace scenarios at w 0.5 only)."""
    out = []
    names = sorted(f.stem for f in DATA.glob('air_*.yaml')) if airspace else SCENARIOS
    for name in names:
        for w in (0.5,) if airspace else WS:
            for label, lim in (('on', {}), ('off', OFF)):
                out.append({'name': f'{name}@{w}', 'limits_label': label, 'w': w,
                            'limits': lim,
                            'file': str(DATA / f'{name}.yaml')})
    for n in () if airspace else (1000, 10000):
        out.append({'name': f'{n} threats', 'limits_label': 'on', 'w': 0.5, 'limits': {},
                    'threats': n})
    return out


def main(argv: list[str] | None = None) -> None:
    """Run both checkouts and write the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('base', type=Path, help='the other checkout (the "before")')
    ap.add_argument('--out', type=Path, default=RESULTS / 'before_after.md')
    ap.add_argument('--repeats', type=int, default=5, help='turns per case (default 5)')
    ap.add_argument('--airspace', action='store_true',
                    help='the airspace scenarios (w 0.5) instead of the threat-only set')
    args = ap.parse_args(argv)
    base_commit, head_commit = short_commit(args.base), short_commit(ROOT)
    before, after = Worker(args.base), Worker(ROOT)
    warm = cases(args.airspace)[0]
    before.plan(warm)
    after.plan(warm)
    rows = []
    turn = 0
    for case in cases(args.airspace):
        runs: dict[int, list[dict]] = {id(before): [], id(after): []}
        for _ in range(max(args.repeats, 1)):
            # Alternate who goes first, so neither always plans on the warmer cache.
            pair = (before, after) if turn % 2 == 0 else (after, before)
            turn += 1
            for w in pair:
                runs[id(w)].append(w.plan(case))
        b, a = _summary(runs[id(before)]), _summary(runs[id(after)])
        rows.append((case, b, a))
        print(case['name'], case['limits_label'], f"{b['ms']:.0f} -> {a['ms']:.0f} ms",
              f"J {b['J']:.4f} -> {a['J']:.4f}", flush=True)
    before.close()
    after.close()
    lines = [
        '# Before and after, side by side',
        '',
        f'Written by `python -m bench before_after` on {time.strftime("%Y-%m-%d %H:%M")}: '
        f'before = `{base_commit}`, after = `{head_commit}`, one worker process each, taking '
        f'turns on every case ({args.repeats} plans per cell and checkout: ms = their median, '
        'min = the least; kernels loaded beforehand) on a 2-core machine shared with other '
        'jobs: read the ratios.',
        '',
        '| case | limits | before ms | after ms | after/before (median) | after/before (min) '
        '| before J | after J | after/before J | feasible before/after |',
        '|---|---|---:|---:|---:|---:|---:|---:|---:|---|',
    ]
    for case, b, a in rows:
        lines.append(f"| {case['name']} | {case['limits_label']} | {b['ms']:.1f} | "
                     f"{a['ms']:.1f} | {a['ms'] / b['ms']:.3f} | {a['min'] / b['min']:.3f} | "
                     f"{b['J']:.4f} | {a['J']:.4f} | {a['J'] / b['J']:.5f} | "
                     f"{b['feasible']}/{a['feasible']} |")
    lines.append('')
    kind = 'airspace scenarios' if args.airspace else '20 threats'
    for label in ('on', 'off'):
        sel = [(b, a) for c, b, a in rows if c['limits_label'] == label and 'file' in c]
        lines.append(
            f'* {kind}, limits {label} ({len(sel)} cases): per-case medians: median '
            f"{statistics.median(b['ms'] for b, _ in sel):.1f} -> "
            f"{statistics.median(a['ms'] for _, a in sel):.1f} ms, worst "
            f"{max(b['ms'] for b, _ in sel):.1f} -> {max(a['ms'] for _, a in sel):.1f} ms; "
            f"per-case least: median {statistics.median(b['min'] for b, _ in sel):.1f} -> "
            f"{statistics.median(a['min'] for _, a in sel):.1f} ms, worst "
            f"{max(b['min'] for b, _ in sel):.1f} -> {max(a['min'] for _, a in sel):.1f} ms; "
            f"J after/before median {statistics.median(a['J'] / b['J'] for b, a in sel):.5f}, "
            f"best {min(a['J'] / b['J'] for b, a in sel):.5f}, "
            f"worst {max(a['J'] / b['J'] for b, a in sel):.5f}")
    args.out.write_text('\n'.join(lines) + '\n')
    print(f'wrote {args.out}')
