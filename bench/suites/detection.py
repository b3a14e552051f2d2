"""Issue 43, item 5: detection plans against paper-cost plans and an SLSQP yardstick.

Usage::

    .venv/bin/python -m bench detection [--seed S] [--quick] [--sizes 20 100] [--fields 2]

Fresh fields (``bench.toolkit.fresh_fields``, uniform and clustered; the seed from the
clock, printed; ``--seed`` replays), the default limits on, w 0.5 and 0.999. Per case:
the paper-cost plan and the detection plan; the bench's own P_detect
(``bench.toolkit.detection_yardstick``) beside the product's; the yardstick (multi-start
SLSQP on w H + (1 - w) L / L_0 at 40 segments from the line, both plans and a perturbed
line); plan times at 20 threats (warm); and ``max_detection`` = the paper plan's P_detect.
Writes bench/results/detection.{md,json} (``--out``).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import statistics
import subprocess
import time

import numpy as np

from bench.toolkit import detection_yardstick as dy
from bench.toolkit.fresh_fields import make_field
from bench.toolkit.repo import RESULTS, ROOT

FAMILIES = ('uniform', 'clustered')
WS = (0.5, 0.999)


def _plan(field, **cfg):
    from threat_planner import PlannerConfig
    from threat_planner.core.planner import plan
    threats, s, g, box = field.problem()
    t0 = time.perf_counter()
    res = plan(threats, s, g, box, PlannerConfig(**cfg))
    return res, (time.perf_counter() - t0) * 1e3


def run_case(family: str, n: int, k: int, seed: int, limits: dict) -> list[dict]:
    field = make_field(family, n, seed, k)
    pos, F = field.positions, field.intensities
    if n <= 20:   # warm: plan once untimed, then time the two side by side
        _plan(field)
        _plan(field, cost_model='detection', method='best')
    paper, paper_ms = _plan(field)
    rows = []
    line = np.array([field.start, field.goal])
    rng = np.random.default_rng([seed, n, k])
    bent = dy.resample(line, 40)
    spread = 0.05 * np.linalg.norm(field.goal - field.start) / 3
    bent[1:-1] += rng.normal(scale=spread, size=(39, 3))
    bent[1:-1] = np.clip(bent[1:-1], field.lo, field.hi)
    for w in WS:
        det, det_ms = _plan(field, cost_model='detection', method='best', w=w)
        own = {lab: dy.hazard(r.path, pos, F) for lab, r in (('paper', paper), ('det', det))}
        rel = max(abs(own['paper'] / paper.detection.hazard - 1),
                  abs(own['det'] / det.detection.hazard - 1))
        y = dy.yardstick(pos, F, field.lo, field.hi, w, limits,
                         [('straight line', line), ('paper plan', paper.path),
                          ('detection plan', det.path), ('perturbed line', bent)])
        prod_obj = dy.objective(det.path, pos, F, w)
        rows.append({
            'id': f'{family}-n{n}-f{k}-w{w:g}', 'family': family, 'n': n, 'k': k, 'w': w,
            'paper_P': -math.expm1(-own['paper']), 'det_P': -math.expm1(-own['det']),
            'product_paper_P': paper.detection.p_detect, 'product_det_P': det.detection.p_detect,
            'H_rel_disagreement': rel, 'det_objective_own': prod_obj,
            'det_objective_product': det.objective, 'det_feasible': bool(det.feasible),
            'det_feasible_bench': dy.feasible(det.path, field.lo, field.hi, limits),
            'yardstick': y['value'], 'yardstick_how': y['how'],
            'yardstick_starts': y['starts'], 'ratio': prod_obj / y['value'],
            'paper_ms': paper_ms, 'det_ms': det_ms})
        r = rows[-1]
        print(f"{r['id']}: P paper {r['paper_P']:.4g} det {r['det_P']:.4g}; obj/yard "
              f"{r['ratio']:.5f}; ms {paper_ms:.0f}/{det_ms:.0f}; H rel {rel:.1e}", flush=True)
    # The bound: P = the paper plan's P_detect.
    p_max = paper.detection.p_detect
    bd, bd_ms = _plan(field, cost_model='detection', method='best', max_detection=p_max)
    own_p = dy.p_detect(bd.path, pos, F)
    yb = dy.bounded_yardstick(pos, F, field.lo, field.hi, p_max, limits,
                              [('paper plan', paper.path), ('bounded plan', bd.path),
                               ('straight line', line)])
    rows.append({'id': f'{family}-n{n}-f{k}-bound', 'family': family, 'n': n, 'k': k,
                 'w': None, 'bound': p_max, 'status': bd.detection_status,
                 'bound_P_own': own_p, 'bound_P_product': bd.detection.p_detect,
                 'bound_L_over_L0': dy.length(bd.path) / np.linalg.norm(field.goal - field.start),
                 'bound_yardstick': yb['value'], 'bound_yardstick_feasible': yb['feasible'],
                 'violated_while_met': bool(bd.detection_status == 'met'
                                            and own_p > p_max * (1 + 1e-6)),
                 'unmet_but_yardstick_feasible': bool(bd.detection_status.startswith('unmet')
                                                      and yb['feasible']),
                 'bound_ms': bd_ms})
    r = rows[-1]
    print(f"{r['id']}: bound {p_max:.4g} status {r['status']!r} own P {own_p:.4g} "
          f"L/L0 {r['bound_L_over_L0']:.5f} yard {yb['value']:.5f}", flush=True)
    return rows


def summary(rows: list[dict]) -> list[str]:
    cases = [r for r in rows if r['w'] is not None]
    out = []
    for w in WS:
        c = [r for r in cases if r['w'] == w]
        if not c:
            continue
        pr = [r['det_P'] / r['paper_P'] for r in c]
        ra = [r['ratio'] for r in c]
        out.append(f"* w {w:g}: {len(c)} cases; P_detect detection/paper median "
                   f"{statistics.median(pr):.4g} (worst {max(pr):.4g}), higher than the paper "
                   f"plan's in {sum(p > 1 for p in pr)}; objective product/yardstick median "
                   f"{statistics.median(ra):.5f}, worst {max(ra):.5f} (target 1.002 / 1.02)")
    small = [r for r in cases if r['n'] == 20]
    if small:
        t = [r['det_ms'] / r['paper_ms'] for r in small]
        out.append(f"* plan time detection/paper at 20 threats (warm): median "
                   f"{statistics.median(t):.2f}x, worst {max(t):.2f}x (target <= 3x)")
    out.append(f"* worst relative disagreement of H (bench vs product): "
               f"{max(r['H_rel_disagreement'] for r in cases):.2e}")
    b = [r for r in rows if r['w'] is None]
    out.append(f"* max_detection = paper P: {len(b)} cases; status met "
               f"{sum(r['status'] == 'met' for r in b)}; **met but own P above the bound: "
               f"{sum(r['violated_while_met'] for r in b)}**; unmet while the yardstick "
               f"found a feasible path: {sum(r['unmet_but_yardstick_feasible'] for r in b)}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seed', type=int)
    ap.add_argument('--quick', action='store_true', help='size 20, one field a family')
    ap.add_argument('--sizes', type=int, nargs='+', default=[20, 100])
    ap.add_argument('--fields', type=int, default=2)
    ap.add_argument('--out', type=Path)
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.fields = [20], 1
    args.out = args.out or (Path('/tmp/detection_quick.md') if args.quick
                            else RESULTS / 'detection.md')
    args.seed = int(time.time()) if args.seed is None else args.seed
    print(f'detection: seed {args.seed} (replay: python -m bench detection --seed '
          f'{args.seed})', flush=True)
    from threat_planner import PlannerConfig
    cfg = PlannerConfig()
    limits = {k: getattr(cfg, k) for k in ('max_climb_deg', 'max_dive_deg',
                                           'min_turn_radius_m', 'min_altitude_m')}
    rows = []
    for n in args.sizes:
        for fam in FAMILIES:
            for k in range(args.fields):
                rows += run_case(fam, n, k, args.seed, limits)
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    lines = ['# Detection plans (issue 43, item 5)', '',
             f'`python -m bench detection --seed {args.seed}` (sizes {args.sizes}, '
             f'{args.fields} field(s) a family), commit {commit} (working tree), '
             f'{time.strftime("%Y-%m-%d %H:%M")}, limits {limits}.', '', *summary(rows), '',
             '| case | P paper | P det | obj/yard | ms paper | ms det | H rel |',
             '|---|---|---|---|---|---|---|']
    lines += [f"| {r['id']} | {r['paper_P']:.4g} | {r['det_P']:.4g} | {r['ratio']:.5f} | "
              f"{r['paper_ms']:.0f} | {r['det_ms']:.0f} | {r['H_rel_disagreement']:.1e} |"
              for r in rows if r['w'] is not None]
    lines += ['', '| bound case | P max | status | own P | L/L0 | yardstick L/L0 |',
              '|---|---|---|---|---|---|']
    lines += [f"| {r['id']} | {r['bound']:.4g} | {r['status']} | {r['bound_P_own']:.4g} | "
              f"{r['bound_L_over_L0']:.5f} | {r['bound_yardstick']:.5f} |"
              for r in rows if r['w'] is None]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text('\n'.join(lines) + '\n')
    args.out.with_suffix('.json').write_text(json.dumps(
        {'seed': args.seed, 'commit': commit, 'limits': limits, 'cases': rows},
        indent=1, default=str) + '\n')
    print('\n'.join(summary(rows)))
    print(f'wrote {args.out}')
    return 0
