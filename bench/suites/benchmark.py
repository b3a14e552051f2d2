"""Benchmark threat_planner inside the flight box against the in-box and limited yardsticks.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python -m bench benchmark                    # full run
    .venv/bin/python -m bench benchmark --quick            # 2 scenarios, 1 repeat
    .venv/bin/python -m bench benchmark --no-ompl --speed  # + 1,000 / 10,000 threats

For every scenario with a reference and w in {0.2, 0.5, 0.8}, one run measures on the same
evaluator (the library's closed-form ``path_cost``), every path inside the box:

* threat_planner's ``paper`` and ``improved`` (the paper's per-vertex pitch / turn check),
  ``best (limits off)`` (climb / dive 90 deg, no turn radius) and ``best (limits on)`` (the
  limited yardstick's climb, dive and turn radius for that scenario): J and the median wall
  time of ``plan`` over ``--repeats`` runs;
* the yardsticks of :mod:`bench.toolkit.yardstick_table`: in-box (bench's own, else
  ``reference_box.json``), limited (bench's own) and the lower bound ``reference.json``
  (leaves the box; a bound only);
* OMPL's RRT* and BIT* on the same J in the box (budgets 10x and 100x ``best (limits off)``),
  the straight line and a 21^3 grid Dijkstra floor.

``--speed`` also plans the shared ``scale1000.yaml`` and ``scale10000.yaml`` once with the
limits on, and reads ``bench/results/cli_scale.json`` (suite ``cli_scale``) for the
command-line target; ``bench/results/speed.md`` (suite ``speed``) is included when present.
Writes ``benchmark.json``, ``benchmark.md`` and ``benchmark.png`` to ``bench/results/``
(``bench/results/quick/`` with ``--quick``) and prints the targets.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
from pathlib import Path
import platform
import statistics
import sys
import time

import numpy as np
from tqdm import tqdm

from bench.toolkit import benchmark_report as br, ompl_planners as om, yardstick_table as yd
from bench.toolkit.cases import LIMITS_OFF, load_reference, QUICK_SCENARIOS, WS
from bench.toolkit.flight_limits import check_limits, flight_limits, Limits
from bench.toolkit.grid import build_grid, GridGraph, grid_floor
from bench.toolkit.repo import command, DATA, RESULTS, SHARED
from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan, PlannerConfig

#: threat_planner rows: label -> PlannerConfig fields (``best (limits on)`` gets its
#: limits per scenario from the limited yardstick).
OURS = {'paper': {'method': 'paper'}, 'improved': {'method': 'improved'},
        br.OFF: {'method': 'best', **LIMITS_OFF}, br.ON: {'method': 'best'}}
OMPL_PLANNERS = ('RRTstar', 'BITstar')
OMPL_LABEL = {'RRTstar': 'RRT*', 'BITstar': 'BIT*', 'InformedRRTstar': 'InformedRRT*'}
MULTIPLIERS = (10, 100)


def _excursion(points: np.ndarray, box) -> float:
    """Farthest distance any point lies outside the box [m] (0 if inside)."""
    out = np.maximum(box.lo - points, 0.0) + np.maximum(points - box.hi, 0.0)
    return float(np.max(np.linalg.norm(out, axis=1)))


def limit_fields(limits: Limits) -> dict:
    """Return the PlannerConfig fields of the limited yardstick's limits."""
    return {'max_climb_deg': limits.max_climb_deg, 'max_dive_deg': limits.max_dive_deg,
            'min_turn_radius_m': limits.min_turn_radius_m}


def _ours(sc, w: float, fields: dict, repeats: int) -> dict:
    """Run one of our rows ``repeats`` times; J (exact), median ms, stage times."""
    walls, results = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w, **fields))
        walls.append(1e3 * (time.perf_counter() - t0))
        results.append(res)
    res = results[-1]
    j = path_cost(res.path, sc.threats.positions, sc.threats.intensities, w).J
    stages = {k: statistics.median(r.timings_ms.get(k, 0.0) for r in results)
              for k in res.timings_ms}
    return {'J': j, 'J_reported': res.cost.J, 'ms': statistics.median(walls),
            'ms_runs': walls, 'timings_ms': stages, 'feasible': bool(res.feasible),
            'n_points': len(res.path), 'path': res.path.tolist()}


def _score(m: dict, y: yd.Yardsticks, box) -> None:
    """Add the ratios to the yardsticks and the in-box flag to a row."""
    m['ratio'] = m['J'] / y.in_box if y.in_box and math.isfinite(m['J']) else math.nan
    pts = np.asarray(m.get('path', []), float)
    m['in_box'] = bool(len(pts) >= 2 and _excursion(pts, box) <= 1e-6 * box.diagonal)


def run_case(sc, w: float, y: yd.Yardsticks, args, grid: GridGraph | None) -> dict:
    """Benchmark every row on one (scenario, w)."""
    limits = y.limits or yd.default_limits(sc)
    case = {'scenario': sc.name, 'w': w, 'n_threats': len(sc.threats),
            'yardsticks': _yardstick_fields(sc, y), 'methods': {}}
    methods = case['methods']
    for label, fields in OURS.items():
        if label in args.skip:
            continue
        if label == br.ON:
            fields = {**fields, **limit_fields(limits)}
        methods[label] = _ours(sc, w, fields, args.repeats)
    straight = np.vstack([sc.start, sc.goal])
    t0 = time.perf_counter()
    j = path_cost(straight, sc.threats.positions, sc.threats.intensities, w).J
    methods['straight line'] = {'J': j, 'ms': 1e3 * (time.perf_counter() - t0),
                                'path': straight.tolist()}
    if grid is not None:
        pts, j, graph_j, secs = grid_floor(grid, sc.threats, w)
        methods[f'grid {args.grid_n}^3'] = {
            'J': j, 'graph_J': graph_j, 'ms': 1e3 * (grid.build_s + secs), 'path': pts.tolist()}
    if not args.no_ompl and om.ompl_available() and br.OFF in methods:
        base_s = methods[br.OFF]['ms'] / 1e3
        budgets = {m: min(m * base_s, args.ompl_cap) for m in MULTIPLIERS}
        for planner in args.ompl_planners:
            runs = om.run_ompl(planner, sc.threats, sc.start, sc.goal, sc.box, w,
                               sorted(set(budgets.values())))
            by_budget = {r['budget_s']: r for r in runs}
            for mult, budget in budgets.items():
                r = dict(by_budget[budget])
                r.update(ms=1e3 * r['elapsed_s'], multiplier=mult,
                         capped=mult * base_s > args.ompl_cap)
                methods[f'{OMPL_LABEL.get(planner, planner)}@{mult}x'] = r
    score_case(case, sc, y)
    return case


def _yardstick_fields(sc, y: yd.Yardsticks) -> dict:
    limits = y.limits or yd.default_limits(sc)
    return {'in_box': y.in_box, 'in_box_source': y.in_box_source, 'box_check': y.box_check,
            'limited': y.limited, 'limits': limits.as_dict(), 'lower_bound': y.lower_bound}


def score_case(case: dict, sc, y: yd.Yardsticks) -> None:
    """Set a case's yardsticks and every row's ratios, in-box flag and limit check."""
    case['yardsticks'] = _yardstick_fields(sc, y)
    limits = y.limits or yd.default_limits(sc)
    methods = case['methods']
    for m in methods.values():
        _score(m, y, sc.box)
    if br.ON in methods:
        m = methods[br.ON]
        pts = np.asarray(m['path'])
        m['limits_ok'] = bool(m['in_box'] and check_limits(pts, limits))
        m['achieved'] = flight_limits(pts)
        m['worst_violation'] = _violation(m['achieved'], limits)
        m['ratio_limited'] = m['J'] / y.limited if y.limited else math.nan


def rescore(out: Path) -> dict:
    """Re-read the yardsticks and re-score the stored paths of ``benchmark.json``.

    A limited yardstick computed after the run must have the limits the row was run with;
    a case whose limits differ keeps no limited ratio.
    """
    bench = br.load_json(out / 'benchmark.json')
    table = yd.YardstickTable()
    for case in bench['cases']:
        sc = load_scenario(DATA / f"{case['scenario']}.yaml")
        y = table.get(sc, case['w'])
        ran = case['yardsticks']['limits']
        if y.limits is not None and y.limits.as_dict() != ran:
            y = yd.Yardsticks(y.in_box, y.in_box_source, y.box_check, None, Limits(
                ran['max_climb_deg'], ran['max_dive_deg'], ran['min_turn_radius_m']),
                y.lower_bound)
        score_case(case, sc, y)
    if 'speed' in bench:
        bench['speed'].update(cli_speed())
    bench['meta']['rescored'] = dt.datetime.now().isoformat(timespec='seconds')
    br.write_outputs(bench, out)
    return bench


def _violation(got: dict, limits: Limits) -> str:
    """Return the worst limit excess of a path as text ('' if none)."""
    parts = []
    for key, lim, sign in (('max_climb_deg', limits.max_climb_deg, 1),
                           ('max_dive_deg', limits.max_dive_deg, 1),
                           ('min_turn_radius_m', limits.min_turn_radius_m, -1)):
        if sign * (got[key] - lim) > 1e-6 * max(1.0, abs(lim)):
            parts.append(f'{key} {got[key]:.2f} vs {lim:g}')
    return '; '.join(parts)


def measure_speed(args) -> dict:
    """plan() once with the limits on at 1,000 and 10,000 threats; the CLI ratio from file."""
    out: dict = {}
    for n in (1000, 10000):
        path = SHARED / f'scale{n}.yaml'
        if not path.exists():
            continue
        sc = load_scenario(path)
        lim = yd.default_limits(sc)
        t0 = time.perf_counter()
        r = plan(sc.threats, sc.start, sc.goal, sc.box,
                 PlannerConfig(w=0.5, method='best', **limit_fields(lim)))
        ms = 1e3 * (time.perf_counter() - t0)
        out[f'plan_{n}_ms'] = ms
        out[f'plan_{n}_ms_note'] = (f'scale{n}.yaml once, cold, limits {lim.max_climb_deg:g}/'
                                    f'{lim.max_dive_deg:g}/{lim.min_turn_radius_m:.0f}, '
                                    f'feasible={r.feasible}, J {r.cost.J:.1f}')
    out.update(cli_speed())
    return out


def cli_speed() -> dict:
    """Return the command-line target and peak memory of ``cli_scale.json`` (if present)."""
    out: dict = {}
    cli = RESULTS / 'cli_scale.json'
    if cli.exists():
        data = json.loads(cli.read_text())
        row = next(r for r in data['rows'] if r['row'] == 'plan, YAML')
        out['cli_ratio'] = row['ratio']
        out['cli_ratio_note'] = (f"cli_scale.md {data['meta']['date']}: YAML {row['ratio']:.1f}x"
                                 + ''.join(f"; {r['row'][6:]} {r['ratio']:.1f}x"
                                           for r in data['rows'] if 'threats_file' in r['row']))
        out['rss_10000_mib'] = row['peak_rss_mib']
        out['rss_10000_mib_note'] = 'peak RSS of threat-planner plan, 10,000-threat YAML'
    return out


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command-line options."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--quick', action='store_true',
                   help='2 scenarios, 1 repeat, OMPL cap 5 s, results in bench/results/quick')
    p.add_argument('--scenarios', nargs='+', help='scenario names (default: all with a '
                   'reference)')
    p.add_argument('--ws', nargs='+', type=float, default=list(WS), help='threat weights')
    p.add_argument('--repeats', type=int, help='runs per method (median time); default 3, '
                   '1 with --quick')
    p.add_argument('--out', type=Path, help='output directory (default bench/results)')
    p.add_argument('--no-ompl', action='store_true', help='skip OMPL')
    p.add_argument('--ompl-planners', nargs='+', default=list(OMPL_PLANNERS),
                   help='planner classes of ompl.geometric')
    p.add_argument('--ompl-cap', type=float, help='cap of every OMPL budget [s] (default 30, '
                   '5 with --quick)')
    p.add_argument('--grid-n', type=int, default=21, help='grid floor nodes per axis')
    p.add_argument('--skip', nargs='*', default=[], choices=list(OURS),
                   help='threat_planner variants to skip')
    p.add_argument('--seed', type=int, default=1, help='OMPL random seed')
    p.add_argument('--scale', action='store_true',
                   help='also run the scaling sweep (suite scale -> scale.md)')
    p.add_argument('--rescore', action='store_true',
                   help='only re-score benchmark.json against the current yardsticks')
    p.add_argument('--speed', action='store_true',
                   help='also plan scale1000/scale10000 with the limits on, read cli_scale.json')
    args = p.parse_args(argv)
    if args.repeats is None:
        args.repeats = 1 if args.quick else 3
    if args.ompl_cap is None:
        args.ompl_cap = 5.0 if args.quick else 30.0
    if args.out is None:
        args.out = RESULTS / 'quick' if args.quick else RESULTS
    if args.scenarios is None and args.quick:
        args.scenarios = list(QUICK_SCENARIOS)
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; return the exit status."""
    args = parse_args(argv)
    given = sys.argv[1:] if argv is None else argv
    if args.rescore:
        bench = rescore(args.out)
        print_targets(br.evaluate_targets(bench['cases'], bench.get('speed')))
        return 0
    bench = run_benchmark(args, command('benchmark', given))
    if args.speed:
        bench['speed'] = measure_speed(args)
        br.write_outputs(bench, args.out)
    if args.scale:
        from bench.suites import scale
        scale.main(['--out', str(args.out), '--repeats', str(args.repeats)]
                   + (['--quick'] if args.quick else []))
    print_targets(br.evaluate_targets(bench['cases'], bench.get('speed')))
    print(f'\nResults in {args.out}')
    return 0


def print_targets(rows: list[dict]) -> None:
    """Print the targets, one line each."""
    print('\nTargets:')
    for r in rows:
        print(f"  {r['verdict']:4s}  {r['target']}: {r['value']:.5g}  [{r['note']}]")


def run_benchmark(args: argparse.Namespace, command: str) -> dict:
    """Run every (scenario, w) case and write the outputs as it goes."""
    refs = load_reference(DATA / 'reference.json')
    names = sorted({name for name, _ in refs})
    if args.scenarios:
        missing = [s for s in args.scenarios if s not in names]
        if missing:
            raise SystemExit(f'no reference for: {", ".join(missing)}')
        names = list(args.scenarios)
    if om.ompl_available():
        om.set_ompl_quiet(args.seed)
    elif not args.no_ompl:
        print('OMPL not importable: skipping OMPL', file=sys.stderr)
    table = yd.YardstickTable()
    bench = {'meta': {
        'date': dt.datetime.now().isoformat(timespec='seconds'), 'command': command,
        'machine': f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, '
                   f'Python {platform.python_version()}',
        'repeats': args.repeats, 'ws': args.ws, 'ompl_cap_s': args.ompl_cap,
        'ompl_planners': [] if args.no_ompl or not om.ompl_available()
        else [OMPL_LABEL.get(p, p) for p in args.ompl_planners],
        'grid_n': args.grid_n}, 'cases': []}
    todo = [(n, w) for n in names for w in args.ws]
    warm = load_scenario(DATA / f'{names[0]}.yaml')
    for fields in OURS.values():
        # Untimed: compiled kernels and imports are paid once, not by the first row.
        plan(warm.threats, warm.start, warm.goal, warm.box,
             PlannerConfig(**{**fields, **limit_fields(yd.default_limits(warm))})
             if fields is OURS[br.ON] else PlannerConfig(**fields))
    bar = tqdm(todo, desc='benchmark', unit='case', file=sys.stderr)
    scenario, grid = None, None
    for name, w in bar:
        bar.set_postfix_str(f'{name}@{w}')
        if scenario is None or scenario.name != name:
            scenario = load_scenario(DATA / f'{name}.yaml')
            grid = build_grid(scenario.threats, scenario.start, scenario.goal, scenario.box,
                              args.grid_n) if args.grid_n > 1 else None
        bench['cases'].append(run_case(scenario, w, table.get(scenario, w), args, grid))
        br.write_outputs(bench, args.out)
    print('\n' + br.summary_table(bench['cases']))
    return bench
