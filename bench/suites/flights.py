"""Fresh simulated flights through pop-up and moving threats: the targets of issue 44.

``python -m bench flights [--seed S] [--sizes 20,100,300,1000] [--per-size 8]`` builds new
fields every run (the seed comes from the clock unless given, and is printed), flies each
with :func:`threat_planner.flight.fly.fly` and reports, per size and overall:

* lethal: flights whose flown path entered a pop-up's lethal sphere (each pop-up appears
  at 2-10 s at least ``commit_s`` + 1.5 s ahead on the path being flown, so an escape
  within the limits exists);
* ``J_flown / J_hindsight``: median and worst (target: median <= 1.05);
* replan latency: p50 and p99 [ms] (targets: p99 <= 50 ms at 20 threats, <= 300 at 1,000);
* ``max_jump_m`` (target <= 0.5), the flown limits, ``reached_goal`` (every flight).

Each flight: a field of :mod:`bench.toolkit.fresh_fields` (families in turn), two of the
threats nearest the straight line moving at 5-30 m/s from take-off, one pop-up ahead on
the plan with a lethal radius, and on every fourth flight a threat removed 0.5 s and the goal
moved 1 s after the pop-up. The results go to ``bench/results/flights.{json,md}``.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
import math
from pathlib import Path
import time

import numpy as np

from bench.toolkit.fresh_fields import FAMILIES, make_field

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / 'bench' / 'results' / 'flights'
TARGETS = {'ratio_median': 1.05, 'p99_ms': {20: 50.0, 1000: 300.0}, 'max_jump_m': 0.5}


def _scenario(field, name: str, velocities: np.ndarray):
    from threat_planner.core.inputs.scenario import Scenario
    threats, start, goal, box = field.problem()
    sc = Scenario(name=name, frame_id='map', description='', box=box, start=start,
                  goal=goal, threats=threats)
    if hasattr(sc, 'velocities') and 'velocities' in Scenario.__dataclass_fields__:
        sc = replace(sc, velocities=velocities)
    return sc


def make_flight(seed: int, n: int, k: int, speed: float, commit_s: float) -> dict:
    """Return one flight's scenario, events document and what was drawn."""
    from threat_planner.core.inputs.config import PlannerConfig
    from threat_planner.core.flight.replan import plan_in_time
    from threat_planner.flight.fly import scenario_timeline
    family = sorted(FAMILIES)[k % len(FAMILIES)]
    field = make_field(family, n, seed, k)
    rng = np.random.default_rng([seed, n, k, 44])
    pos = field.positions
    line = field.goal - field.start
    u = np.clip((pos - field.start) @ line / (line @ line), 0.0, 1.0)
    near = np.argsort(np.linalg.norm(field.start + u[:, None] * line - pos, axis=1))
    movers = near[:2]
    vel = np.zeros_like(pos)
    for i in movers:
        d = rng.normal(size=3)
        d[2] *= 0.3
        vel[i] = rng.uniform(5.0, 30.0) * d / np.linalg.norm(d)
    sc = _scenario(field, f'{family}-n{n}-k{k}', vel)
    # The pop-up goes on the path the flight starts on: its first plan, in time.
    path = plan_in_time(scenario_timeline(sc), sc.start, sc.goal, sc.box, PlannerConfig(),
                        speed).points
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    t_pop = float(rng.uniform(2.0, 10.0))
    ahead = speed * (t_pop + commit_s + rng.uniform(1.5, 3.0))
    ahead = min(ahead, 0.8 * arc[-1])
    t_pop = min(t_pop, max(0.5, ahead / speed - commit_s - 1.5))
    where = np.array([np.interp(ahead, arc, path[:, c]) for c in range(3)])
    f_mean = float(np.mean(field.intensities))
    events = []
    if 'velocities' not in type(sc).__dataclass_fields__:   # no scenario key yet
        events += [{'t': 0.0, 'move_threat': {'index': int(i), 'velocity': vel[i].tolist()}}
                   for i in movers]
    events.append({'t': round(t_pop, 3), 'add_threat': {
        'position': where.tolist(), 'intensity': 2.0 * f_mean,
        'lethal_radius': float(rng.uniform(5.0, 10.0))}})
    if k % 4 == 3:
        events.append({'t': round(t_pop + 0.5, 3), 'remove_threat': {'index': int(near[2])}})
        g = field.goal.copy()
        g[:2] = field.hi[:2] * rng.uniform(0.7, 0.95, 2)
        events.append({'t': round(t_pop + 1.0, 3), 'goal': g.tolist()})
    return {'scenario': sc, 'events': {'events': events}, 'family': family, 'n': n, 'k': k,
            'movers': [int(i) for i in movers], 't_pop': t_pop}


def run_flight(case: dict, speed: float, commit_s: float) -> dict:
    """Fly one case; return its row of the results."""
    from threat_planner.core.inputs.config import PlannerConfig
    from threat_planner.flight.events import parse_events
    from threat_planner.flight.fly import fly
    cfg = PlannerConfig()
    t0 = time.perf_counter()
    rep = fly(case['scenario'], parse_events(case['events']), cfg, speed,
              commit_s=commit_s).as_dict()
    wall = time.perf_counter() - t0
    lat = [r['latency_ms'] for r in rep['replans'][1:] if r.get('latency_ms') is not None]
    return {
        'name': case['scenario'].name, 'n': case['n'], 'family': case['family'],
        'events': case['events']['events'], 'J_flown': rep['J_flown'],
        'J_hindsight': rep['J_hindsight'], 'ratio': rep['J_flown'] / rep['J_hindsight'],
        'latency_ms': lat, 'first_plan_ms': rep['replans'][0].get('latency_ms'),
        'failed_replans': sum(not r['ok'] for r in rep['replans']),
        'max_jump_m': rep['max_jump_m'], 'max_tracking_m': rep['max_tracking_m'],
        'limits_feasible': rep['flown_limits']['feasible'],
        'limits': rep['flown_limits'], 'reached_goal': rep['reached_goal'],
        'lethal_entries': rep['lethal_entries'], 'flight_s': rep['flown']['t'][-1],
        'wall_s': wall,
    }


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


def summarise(rows: list[dict]) -> dict:
    """Return the per-size and overall figures of the module docstring."""
    def one(sel: list[dict]) -> dict:
        lat = [v for r in sel for v in r['latency_ms']]
        ratios = [r['ratio'] for r in sel]
        return {'flights': len(sel), 'lethal': sum(bool(r['lethal_entries']) for r in sel),
                'ratio_median': float(np.median(ratios)), 'ratio_worst': max(ratios),
                'latency_p50_ms': _pct(lat, 50), 'latency_p99_ms': _pct(lat, 99),
                'latency_max_ms': max(lat, default=math.nan),
                'max_jump_m': max(r['max_jump_m'] for r in sel),
                'limits_broken': sum(not r['limits_feasible'] for r in sel),
                'not_reached': sum(not r['reached_goal'] for r in sel),
                'failed_replans': sum(r['failed_replans'] for r in sel)}
    sizes = sorted({r['n'] for r in rows})
    return {'by_size': {n: one([r for r in rows if r['n'] == n]) for n in sizes},
            'all': one(rows)}


def _args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m bench flights',
                                 description=__doc__.split('\n')[0])
    ap.add_argument('--seed', type=int, default=None, help='replay a run (default: clock)')
    ap.add_argument('--sizes', default='20,100,300,1000', help='threat counts')
    ap.add_argument('--per-size', type=int, default=8, help='flights per size')
    ap.add_argument('--speed', type=float, default=20.0, help='cruise speed [m/s]')
    ap.add_argument('--commit', type=float, default=2.0, help='commit_s [s]')
    ap.add_argument('--out', type=Path, default=OUT, help='results (.json and .md)')
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Fly the fresh cases and write the report."""
    args = _args(argv)
    seed = args.seed if args.seed is not None else int(time.time()) % 2**31
    print(f'flights: seed {seed} (replay with --seed {seed})', flush=True)
    # The first flight pays for the kernels' loading; fly a small one untimed first.
    run_flight(make_flight(seed, 20, 0, args.speed, args.commit), args.speed, args.commit)
    rows = []
    for n in (int(v) for v in args.sizes.split(',')):
        for k in range(args.per_size):
            case = make_flight(seed, n, k, args.speed, args.commit)
            row = run_flight(case, args.speed, args.commit)
            rows.append(row)
            print(f"  {row['name']}: J_flown/J_hindsight {row['ratio']:.3f}, replans "
                  f"{', '.join(f'{v:.0f}' for v in row['latency_ms'])} ms, jump "
                  f"{row['max_jump_m']:.2g} m, limits {row['limits_feasible']}, reached "
                  f"{row['reached_goal']}, lethal {len(row['lethal_entries'])}", flush=True)
    summary = summarise(rows)
    write(args.out, seed, rows, summary, args)
    print(json.dumps(summary['all'], indent=1))
    return 0


def write(out: Path, seed: int, rows: list[dict], summary: dict,
          args: argparse.Namespace) -> None:
    """Write ``out``.json (every row) and ``out``.md (the table)."""
    from bench.toolkit.checkouts import short_commit
    commit = short_commit(ROOT)
    doc = {'seed': seed, 'commit': commit, 'date': time.strftime('%Y-%m-%d %H:%M'),
           'speed_mps': args.speed, 'commit_s': args.commit, 'targets': TARGETS,
           'summary': summary, 'rows': rows}
    out.with_suffix('.json').write_text(json.dumps(doc, indent=1, default=float) + '\n')
    lines = [f'# Simulated flights (issue 44 targets), seed {seed}', '',
             f'`python -m bench flights --seed {seed}` on {doc["date"]} at {commit}: '
             f'{len(rows)} fresh flights at {args.speed:g} m/s, commit_s {args.commit:g} s, '
             'default limits, w 0.5; a 2-core machine shared with other jobs. Latency: '
             'the replans after the first plan.', '',
             '| threats | flights | lethal | J_flown/J_hindsight median | worst | '
             'latency p50 ms | p99 ms | max ms | max jump m | limits broken | '
             'not reached | failed replans |',
             '|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|']
    for n, s in list(summary['by_size'].items()) + [('all', summary['all'])]:
        lines.append(f"| {n} | {s['flights']} | {s['lethal']} | {s['ratio_median']:.3f} | "
                     f"{s['ratio_worst']:.3f} | {s['latency_p50_ms']:.0f} | "
                     f"{s['latency_p99_ms']:.0f} | {s['latency_max_ms']:.0f} | "
                     f"{s['max_jump_m']:.2g} | {s['limits_broken']} | {s['not_reached']} | "
                     f"{s['failed_replans']} |")
    out.with_suffix('.md').write_text('\n'.join(lines) + '\n')
