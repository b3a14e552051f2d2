"""Benchmark threat_planner against the reference yardstick, OMPL and simple floors.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python bench/run_benchmark.py                 # full run, ~25 min
    .venv/bin/python bench/run_benchmark.py --quick         # 2 scenarios, 1 repeat
    .venv/bin/python bench/run_benchmark.py --scenarios uniform20_0 --repeats 5
    .venv/bin/python bench/run_benchmark.py --scale         # also the scaling sweep
    .venv/bin/python bench/run_benchmark.py --scale-only    # only the scaling sweep

For every scenario in the shared scenario directory that has a reference J, and w in
{0.2, 0.5, 0.8}, one run measures on the same evaluator (the library's closed-form
``path_cost``):

* threat_planner's ``paper`` and ``improved`` methods and three ``best`` variants (J and
  wall time of ``plan``, median of ``--repeats`` runs): ``best`` (the product default:
  confined to the box, 45 deg pitch and 60 deg turn limits), ``best (no angle limits)``
  (confined, limits off: OMPL's and the grid's rules) and ``best (reference rules)``
  (unconfined, limits off: the reference's rules);
* the reference J from ``reference.json`` (its L-BFGS was unbounded, so its paths may
  leave the flight box, and it has no angle limits);
* OMPL's RRT* and BIT* in a ``RealVectorStateSpace(3)`` over the box optimising the same J
  (``motionCost`` = closed-form J of the straight motion), with time budgets of 10x and
  100x our ``best (no angle limits)`` time for that case, each capped at ``--ompl-cap`` s;
* floors: the straight line S->T and Dijkstra on a 21^3 26-connected grid with exact edge J.

Writes ``benchmark.json`` (raw numbers and paths), ``benchmark.md`` (tables and the
targets) and ``benchmark.png`` (J / reference J against time) to ``bench/results/``
(``bench/results/quick/`` with ``--quick``), and prints the targets as PASS/MISS.
``--scale`` runs ``bench/run_scale.py`` too (``scale.{json,md,png}``).
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

import _repo  # noqa: F401  (puts the repository root on sys.path)
import bench_tools as bt
import numpy as np
from tqdm import tqdm

from threat_planner.core.cost import path_cost
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.scenario import load_scenario
from threat_planner.core.smoothing import check_angles

RESULTS = Path(__file__).resolve().parent / 'results'
WS = (0.2, 0.5, 0.8)
QUICK_SCENARIOS = ('uniform20_0', 'weak20_0')
#: The like-for-like peer of OMPL and the grid (same box, no angle limits).
BOX_PEER = 'best (no angle limits)'
#: The like-for-like peer of the reference (unconfined, no angle limits).
REF_PEER = 'best (reference rules)'
#: threat_planner variants: label -> PlannerConfig fields.
OURS = {
    'paper': {'method': 'paper'},
    'improved': {'method': 'improved'},
    'best': {'method': 'best'},
    BOX_PEER: {'method': 'best', **bt.NO_ANGLE_LIMITS},
    REF_PEER: {'method': 'best', 'confine_to_box': False, **bt.NO_ANGLE_LIMITS},
}
#: The default angle limits, which every method's path is checked against.
DEFAULT_LIMITS = (PlannerConfig().max_pitch_deg, PlannerConfig().max_turn_deg)
#: The rules each method plays by: (stays in the box, angle limits).
RULES = {'reference (yardstick)': ('no', 'none'), REF_PEER: ('no', 'none'),
         BOX_PEER: ('yes', 'none'), 'straight line': ('-', 'none')}
#: One line per variant of ours, for the notes in benchmark.md.
VARIANT_NOTES = {
    'paper': 'the paper\'s method (confined, default angle limits).',
    'improved': 'the paper\'s method with our fixes (confined, default angle limits).',
    'best': 'our product default: method `best`, confined to the box, pitch <= '
            f'{DEFAULT_LIMITS[0]:g} deg and turn <= {DEFAULT_LIMITS[1]:g} deg; '
            'no other method here is held to those limits.',
    BOX_PEER: '`best`, confined, `max_pitch_deg=90, max_turn_deg=180` (limits off): the '
              'like-for-like peer of OMPL and the grid, and the base of OMPL\'s budgets.',
    REF_PEER: '`best`, `confine_to_box=False`, limits off: the like-for-like peer of the '
              'reference, whose unbounded L-BFGS leaves the box and has no angle limits.',
}
OMPL_PLANNERS = ('RRTstar', 'BITstar')
OMPL_LABEL = {'RRTstar': 'RRT*', 'BITstar': 'BIT*', 'InformedRRTstar': 'InformedRRT*',
              'SORRTstar': 'SORRT*', 'AORRTC': 'AORRTC'}
MULTIPLIERS = (10, 100)

# Targets.
RATIO_MEDIAN = 1.01
RATIO_WORST = 1.05
MS_20 = 20.0
MS_1000 = 300.0
MS_10000 = 3000.0
MEM_10000_MB = 1024.0


def _excursion(points: np.ndarray, box) -> float:
    """Farthest distance any point lies outside the box [m] (0 if inside)."""
    out = np.maximum(box.lo - points, 0.0) + np.maximum(points - box.hi, 0.0)
    return float(np.max(np.linalg.norm(out, axis=1)))


def _ours(sc, w: float, fields: dict, repeats: int) -> dict:
    """Run one threat_planner variant ``repeats`` times; J, median ms, stage times."""
    walls, results = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w, **fields))
        walls.append(1e3 * (time.perf_counter() - t0))
        results.append(res)
    res = results[-1]
    js = [r.cost.J for r in results]
    # Score with the evaluator every method shares (the library's own path_cost).
    j = path_cost(res.path, sc.threats.positions, sc.threats.intensities, w).J
    stages = {k: statistics.median(r.timings_ms.get(k, 0.0) for r in results)
              for k in res.timings_ms}
    return {'J': j, 'J_reported': res.cost.J, 'J_spread': max(js) - min(js),
            'ms': statistics.median(walls), 'ms_runs': walls, 'timings_ms': stages,
            'feasible': bool(res.feasible), 'max_pitch_deg': res.angles.max_pitch_deg,
            'max_turn_deg': res.angles.max_turn_deg,
            'box_excursion_m': _excursion(res.path, sc.box),
            'n_points': len(res.path), 'path': res.path.tolist()}


def run_case(sc, w: float, ref: dict, args, grid: bt.GridGraph | None) -> dict:
    """Benchmark every method on one (scenario, w)."""
    case = {'scenario': sc.name, 'w': w, 'n_threats': len(sc.threats),
            'reference': ref, 'methods': {}}
    methods = case['methods']
    for label, fields in OURS.items():
        if label in args.skip:
            continue
        methods[label] = _ours(sc, w, fields, args.repeats)

    t0 = time.perf_counter()
    straight = np.vstack([sc.start, sc.goal])
    j = path_cost(straight, sc.threats.positions, sc.threats.intensities, w).J
    methods['straight line'] = {'J': j, 'ms': 1e3 * (time.perf_counter() - t0),
                                'path': straight.tolist()}
    if grid is not None:
        pts, j, graph_j, secs = bt.grid_floor(grid, sc.threats, w)
        methods[f'grid {args.grid_n}^3'] = {
            'J': j, 'graph_J': graph_j, 'ms': 1e3 * (grid.build_s + secs),
            'build_ms': 1e3 * grid.build_s, 'search_ms': 1e3 * secs, 'path': pts.tolist()}

    if not args.no_ompl and bt.ompl_available():
        base = next((methods[k] for k in (BOX_PEER, 'best') if k in methods), None)
        base_s = base['ms'] / 1e3 if base else 0.1
        budgets = {m: min(m * base_s, args.ompl_cap) for m in MULTIPLIERS}
        for planner in args.ompl_planners:
            runs = bt.run_ompl(planner, sc.threats, sc.start, sc.goal, sc.box, w,
                               sorted(set(budgets.values())))
            by_budget = {r['budget_s']: r for r in runs}
            for mult, budget in budgets.items():
                r = dict(by_budget[budget])
                r.update(ms=1e3 * r['elapsed_s'], multiplier=mult,
                         capped=mult * base_s > args.ompl_cap)
                methods[f'{OMPL_LABEL.get(planner, planner)}@{mult}x'] = r
    for m in methods.values():
        m['ratio'] = m['J'] / ref['J'] if ref and math.isfinite(m['J']) else math.nan
        if len(m.get('path', [])) >= 2:
            m['in_default_limits'] = bool(check_angles(np.asarray(m['path']),
                                                       *DEFAULT_LIMITS).feasible)
    return case


def _fmt_j(m: dict | None) -> str:
    if not m or not math.isfinite(m.get('J', math.inf)):
        return '-'
    flag = ' !' if m.get('feasible') is False else ''
    return f"{m['J']:.2f} ({m['ratio']:.3f}){flag}"


def _rules(label: str) -> tuple[str, str]:
    """Return (stays in the box, angle limits) of a method, by its label."""
    if label in RULES:
        return RULES[label]
    if label in OURS:
        return 'yes', f'{DEFAULT_LIMITS[0]:g}/{DEFAULT_LIMITS[1]:g}'
    return 'yes', 'none'   # grid and OMPL


def _fmt_ms(ms: float) -> str:
    return f'{ms:.0f}' if ms >= 10 else f'{ms:.1f}'


def _median(xs: list[float]) -> float:
    xs = [x for x in xs if math.isfinite(x)]
    return statistics.median(xs) if xs else math.nan


def summary_rows(cases: list[dict]) -> list[tuple]:
    """Return rows (method, cases, median ratio, worst ratio, median ms, in limits).

    The last field counts the cases whose path meets the default angle limits (None
    where there are no paths, as for the reference).
    """
    labels: list[str] = []
    for c in cases:
        labels += [k for k in c['methods'] if k not in labels]
    rows = []
    for label in labels:
        ms = [c['methods'][label] for c in cases if label in c['methods']]
        ratios = [m['ratio'] for m in ms]
        finite = [r for r in ratios if math.isfinite(r)]
        rows.append((label, len(ms), _median(ratios), max(finite) if finite else math.nan,
                     _median([m['ms'] for m in ms]),
                     sum(bool(m.get('in_default_limits')) for m in ms)))
    rows.append(('reference (yardstick)', len(cases), 1.0, 1.0,
                 _median([1e3 * c['reference']['seconds'] for c in cases]), None))
    return rows


def summary_table(cases: list[dict]) -> str:
    """Return the Markdown summary, one row per method."""
    lim = f'{DEFAULT_LIMITS[0]:g}/{DEFAULT_LIMITS[1]:g}'
    lines = ['| method | in box | angle limits | cases | median J/ref | worst J/ref | median ms '
             f'| path meets {lim} deg |', '|---|---|---|---:|---:|---:|---:|---:|']
    for label, n, med, worst, ms, ok in summary_rows(cases):
        box, limits = _rules(label)
        ok_s = '-' if ok is None else f'{ok}/{n}'
        lines.append(f'| {label} | {box} | {limits} | {n} | {med:.3f} | {worst:.3f} | '
                     f'{_fmt_ms(ms)} | {ok_s} |')
    return '\n'.join(lines)


def ours_table(cases: list[dict]) -> str:
    """Return the Markdown table of threat_planner's methods, the reference and the floors."""
    labels = [k for k in list(OURS) + ['grid', 'straight line']]
    head = ['scenario', 'w', 'N', 'ref J']
    for lab in labels:
        head += [f'{lab} J (ratio)', 'ms'] if lab != 'straight line' else [f'{lab} J (ratio)']
    head.append(f'{REF_PEER}: out of box [m]')
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * 3 + '---:|' * (len(head) - 3)]
    for c in cases:
        m = c['methods']
        grid = next((v for k, v in m.items() if k.startswith('grid')), None)
        row = [c['scenario'], f"{c['w']:.1f}", str(c['n_threats']), f"{c['reference']['J']:.2f}"]
        for lab in labels:
            v = grid if lab == 'grid' else m.get(lab)
            row.append(_fmt_j(v))
            if lab != 'straight line':
                row.append(_fmt_ms(v['ms']) if v else '-')
        unc = m.get(REF_PEER)
        row.append(f"{unc['box_excursion_m']:.1f}" if unc else '-')
        lines.append('| ' + ' | '.join(row) + ' |')
    return '\n'.join(lines)


def ompl_table(cases: list[dict]) -> str:
    """Return the Markdown table of OMPL against ``best (no angle limits)`` (same rules)."""
    labels: list[str] = []
    for c in cases:
        labels += [k for k in c['methods'] if '@' in k and k not in labels]
    if not labels:
        return '_OMPL not run._'
    head = ['scenario', 'w', f'{BOX_PEER} J (ratio)', 'ms']
    for lab in labels:
        head += [f'{lab} J (ratio)', 'budget s']
    lines = ['| ' + ' | '.join(head) + ' |', '|---|---|' + '---:|' * (len(head) - 2)]
    for c in cases:
        m = c['methods']
        best = m.get(BOX_PEER)
        row = [c['scenario'], f"{c['w']:.1f}", _fmt_j(best), _fmt_ms(best['ms']) if best else '-']
        for lab in labels:
            v = m.get(lab)
            row.append(_fmt_j(v))
            cap = ' (cap)' if v and v['capped'] else ''
            row.append('-' if not v else f"{v['budget_s']:.2f}{cap}")
        lines.append('| ' + ' | '.join(row) + ' |')
    return '\n'.join(lines)


def _verdict(ok: bool | None) -> str:
    return 'n/a' if ok is None else ('PASS' if ok else 'MISS')


def evaluate_targets(bench: dict | None, scale: dict | None) -> list[dict]:
    """Check every target; each row has name, value, limit, verdict and margin text."""
    rows: list[dict] = []

    def add(name: str, value: float, limit: float, unit: str = '', note: str = '') -> None:
        ok = None if not math.isfinite(value) else value <= limit
        margin = '' if ok is None else f'{limit - value:+.3g}{unit} ({value / limit:.2f}x)'
        rows.append({'target': name, 'value': value, 'limit': limit, 'verdict': _verdict(ok),
                     'margin': margin, 'note': note})

    cases = bench['cases'] if bench else []
    ratios = [c['methods'][REF_PEER]['ratio'] for c in cases if REF_PEER in c['methods']]
    med, worst = _median(ratios), max(ratios) if ratios else math.nan
    note = 'reference rules (unconfined, no angle limits): like for like'
    add(f'{REF_PEER}: median J/ref <= {RATIO_MEDIAN}', med, RATIO_MEDIAN, '', note)
    add(f'{REF_PEER}: worst J/ref <= {RATIO_WORST}', worst, RATIO_WORST, '', note)
    rrt = [(c, c['methods']['RRT*@10x']) for c in cases
           if 'RRT*@10x' in c['methods'] and BOX_PEER in c['methods']]
    if rrt:
        # Our J / RRT* J must stay below 1 on every case; report the worst case.
        worst_c, worst_r = max(((c, c['methods'][BOX_PEER]['J'] / r['J']) for c, r in rrt),
                               key=lambda x: x[1])
        n_win = sum(c['methods'][BOX_PEER]['J'] < r['J'] for c, r in rrt)
        ok = n_win == len(rrt)
        rows.append({'target': f'{BOX_PEER} J < RRT*@10x J on every case', 'value': worst_r,
                     'limit': 1.0, 'verdict': _verdict(ok),
                     'margin': f'{n_win}/{len(rrt)} cases; worst ours/RRT* = {worst_r:.3f} '
                               f"({worst_c['scenario']}@{worst_c['w']})",
                     'note': 'both confined, no angle limits; budget 10x our time'})
    feas = [c['methods']['best']['feasible'] for c in cases if 'best' in c['methods']]
    if feas:
        n_bad = sum(not f for f in feas)
        rows.append({'target': 'best: path meets its angle limits on every case',
                     'value': n_bad, 'limit': 0, 'verdict': _verdict(n_bad == 0),
                     'margin': f'{len(feas) - n_bad}/{len(feas)} cases feasible',
                     'note': f'value: infeasible cases; limits {DEFAULT_LIMITS[0]:g}/'
                             f'{DEFAULT_LIMITS[1]:g} deg'})
    runs = [m for c in cases for k, m in c['methods'].items() if '@' in k]
    if runs:
        worst = max(m['rel_diff'] if math.isfinite(m['rel_diff']) else math.inf for m in runs)
        calls = min(m['motion_calls'] for m in runs)
        rows.append({'target': 'check: OMPL cost of its path == path_cost J (rel <= 1e-6)',
                     'value': worst, 'limit': 1e-6, 'verdict': _verdict(worst <= 1e-6),
                     'margin': f'{len(runs)} runs; fewest motionCost calls in a run: {calls}',
                     'note': 'inf: a run found no exact solution'})
    for variant in ('best', BOX_PEER):
        _speed_targets(add, variant, cases, scale)
    r = {s['n']: s for s in (scale or {}).get('sizes', [])
         if s.get('variant', 'best') == 'best'}.get(10000)
    add(f'10,000 threats: peak memory < {MEM_10000_MB:.0f} MiB', r['peak_rss_mb']
        if r else math.nan, MEM_10000_MB, ' MiB', 'peak RSS of the whole process (best)'
        if r else 'scale sweep not run')
    return rows


def _speed_targets(add, variant: str, cases: list[dict], scale: dict | None) -> None:
    """Add the speed targets of one variant (scaling sweep, scale files, benchmark cases)."""
    sizes = {r['n']: r for r in (scale or {}).get('sizes', [])
             if r.get('variant', 'best') == variant}
    files = {r['name']: r for r in (scale or {}).get('files', [])
             if r.get('variant', 'best') == variant}
    for n, limit in ((20, MS_20), (1000, MS_1000), (10000, MS_10000)):
        r = sizes.get(n)
        add(f'{variant}: {n} threats total <= {limit:.0f} ms (sweep)',
            r['timings_ms']['total_ms'] if r else math.nan, limit, ' ms',
            f"wall {r['wall_ms']:.0f} ms" if r else 'scale sweep not run')
        f = files.get(f'scale{n}')
        if f:
            add(f'{variant}: {n} threats total <= {limit:.0f} ms (scale{n}.yaml)',
                f['timings_ms']['total_ms'], limit, ' ms', f"wall {f['wall_ms']:.0f} ms")
    small = [c['methods'][variant]['timings_ms'].get('total_ms', math.nan) for c in cases
             if c['n_threats'] <= 24 and variant in c['methods']]
    if small:
        add(f'{variant}: ~20 threats total <= {MS_20:.0f} ms (worst benchmark case)',
            max(small), MS_20, ' ms', f'{len(small)} cases with 16-24 threats; '
            f'median {_median(small):.0f} ms')


def targets_table(rows: list[dict]) -> str:
    """Return the Markdown table of the targets."""
    lines = ['| target | value | verdict | margin | note |', '|---|---:|---|---|---|']
    for r in rows:
        lines.append(f"| {r['target']} | {r['value']:.5g} | **{r['verdict']}** | "
                     f"{r['margin']} | {r['note']} |")
    return '\n'.join(lines)


def print_targets(rows: list[dict]) -> None:
    """Print the targets, one line each."""
    print('\nTargets:')
    for r in rows:
        print(f"  {r['verdict']:4s}  {r['target']}: {r['value']:.5g}  {r['margin']}"
              + (f"  [{r['note']}]" if r['note'] else ''))


def render_markdown(bench: dict, scale: dict | None) -> str:
    """Render the whole ``benchmark.md`` from the JSON results."""
    cases = bench['cases']
    meta = bench['meta']
    cap = meta['ompl_cap_s']
    parts = [
        '# Benchmark', '',
        f"Generated {meta['date']} by `{meta['command']}` on {meta['machine']}.", '',
        'Every J is the library\'s closed-form `path_cost` of the method\'s final path; ratios '
        'are to the reference yardstick\'s J (`reference.json`). Times are wall-clock '
        f"milliseconds, median of {meta['repeats']} run(s) for threat_planner's methods.", '',
        '**Rules.** Only our methods enforce the UAV angle limits; the reference, the grid and '
        'OMPL ignore them, and the reference\'s final L-BFGS was unbounded, so its paths '
        'leave the flight box (e.g. uniform20_0@0.8 reaches z = 142 m with the box top at '
        '100 m). Each comparison is therefore made like for like: the J/ref targets on '
        f'`{REF_PEER}`, the OMPL target on `{BOX_PEER}`. Our variants:', '',
        *[f'* `{k}`: {v}' for k, v in VARIANT_NOTES.items()], '',
        'A J cell marked "!" is a path that breaks its own variant\'s angle limits '
        '(infeasible); the summary counts, for every method, the paths within the default '
        f'{DEFAULT_LIMITS[0]:g} deg pitch / {DEFAULT_LIMITS[1]:g} deg turn limits.', '',
        f"OMPL ({', '.join(meta['ompl_planners'])}) plans in a `RealVectorStateSpace(3)` over "
        'the box with a Python `OptimizationObjective` whose `motionCost` is the closed-form J '
        'of the straight motion (`stateCost` zero, `motionCostHeuristic` (1-w)*distance); the '
        'largest relative difference between OMPL\'s own cost of its solution and `path_cost` '
        f"of that path was {meta.get('ompl_max_rel_diff', float('nan')):.1e} over all runs "
        '(see the targets table for the check and the motionCost call counts). '
        f'Budgets are 10x and 100x our `{BOX_PEER}` time for the case, each capped at '
        f'{cap:g} s '
        '(marked "(cap)"); a planner is solved to the smaller budget then resumed to the larger. '
        f"The grid floor is Dijkstra on a {meta['grid_n']}^3 26-connected grid over the box "
        '(start and goal joined to their neighbouring nodes) with exact edge J; its time '
        'includes computing every edge\'s J.', '',
        '## Summary', '', summary_table(cases), '',
        '## Targets', '', targets_table(evaluate_targets(bench, scale)), '',
        '## threat_planner, reference and floors', '',
        'Cells are J (J / reference J); ms is wall time of one `plan` call. The last column is '
        f'how far the `{REF_PEER}` path leaves the box.', '',
        ours_table(cases), '',
        '## OMPL at 10x and 100x our time (all confined to the box, no angle limits)', '',
        ompl_table(cases), '',
        '![J ratio against time](benchmark.png)', '',
    ]
    if scale:
        parts += ['## Scaling', '', 'See [scale.md](scale.md).', '']
    return '\n'.join(parts)


def plot(cases: list[dict], path: Path) -> None:
    """Plot J / reference J against time per method, log time axis."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    labels: list[str] = []
    for c in cases:
        labels += [k for k in c['methods'] if k not in labels]
    markers = 'osD^v<>phX*P'
    fig, ax = plt.subplots(figsize=(9, 6))
    cmap = plt.get_cmap('tab10')
    for i, lab in enumerate(labels):
        pts = [(c['methods'][lab]['ms'] / 1e3, c['methods'][lab]['ratio']) for c in cases
               if lab in c['methods'] and math.isfinite(c['methods'][lab]['ratio'])]
        if pts:
            x, y = zip(*pts)
            ax.scatter(x, y, s=28, marker=markers[i % len(markers)], color=cmap(i % 10),
                       label=lab, alpha=0.8)
    ref = [(c['reference']['seconds'], 1.0) for c in cases]
    if ref:
        x, y = zip(*ref)
        ax.scatter(x, y, s=40, marker='x', color='k', label='reference (unbounded)')
    ax.axhline(1.0, color='k', lw=0.8, ls='--')
    ax.set_xscale('log')
    ax.set_yscale('log')
    ax.set_xlabel('wall time per plan [s] (log)')
    ax.set_ylabel('J / reference J (log)')
    ax.set_title('J ratio to the reference against time, every scenario and w')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8, loc='upper right', ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _clean(obj):
    """Replace inf and nan with None for strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def _unclean(obj):
    """Inverse of :func:`_clean` for the numeric fields that matter (None -> inf/nan)."""
    if isinstance(obj, dict):
        out = {k: _unclean(v) for k, v in obj.items()}
        for k in ('J', 'J_ompl'):
            if k in out and out[k] is None:
                out[k] = math.inf
        for k in ('ratio', 'rel_diff'):
            if k in out and out[k] is None:
                out[k] = math.nan
        return out
    if isinstance(obj, list):
        return [_unclean(v) for v in obj]
    return obj


def load_json(path: Path) -> dict | None:
    """Read a results file written by this module, or None if absent."""
    return _unclean(json.loads(path.read_text())) if path.exists() else None


def write_outputs(bench: dict, out: Path) -> None:
    """Write benchmark.json, benchmark.md and benchmark.png, and print the targets."""
    out.mkdir(parents=True, exist_ok=True)
    diffs = [m['rel_diff'] for c in bench['cases'] for k, m in c['methods'].items()
             if '@' in k and math.isfinite(m.get('rel_diff', math.nan))]
    bench['meta']['ompl_max_rel_diff'] = max(diffs) if diffs else math.nan
    (out / 'benchmark.json').write_text(json.dumps(_clean(bench), indent=1))
    scale = load_json(out / 'scale.json')
    (out / 'benchmark.md').write_text(render_markdown(bench, scale))
    if bench['cases']:
        plot(bench['cases'], out / 'benchmark.png')


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
    p.add_argument('--scenario-dir', type=Path, default=bt.default_scenario_dir())
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
    p.add_argument('--scale', action='store_true', help='also run the scaling sweep')
    p.add_argument('--scale-only', action='store_true', help='only run the scaling sweep')
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
    command = 'python bench/run_benchmark.py ' + ' '.join(given)
    if not args.scale_only:
        bench = run_benchmark(args, command.strip())
    else:
        bench = load_json(args.out / 'benchmark.json')
    if args.scale or args.scale_only:
        import run_scale
        scale_argv = ['--out', str(args.out), '--repeats', str(args.repeats)]
        scale_argv += ['--quick'] if args.quick else []
        run_scale.main(scale_argv)
        if bench:
            write_outputs(bench, args.out)
    scale = load_json(args.out / 'scale.json')
    print_targets(evaluate_targets(bench, scale))
    print(f'\nResults in {args.out}')
    return 0


def run_benchmark(args: argparse.Namespace, command: str) -> dict:
    """Run every (scenario, w) case and write the outputs as it goes."""
    refs = bt.load_reference(args.scenario_dir / 'reference.json')
    names = sorted({name for name, _ in refs})
    if args.scenarios:
        missing = [s for s in args.scenarios if s not in names]
        if missing:
            raise SystemExit(f'no reference for: {", ".join(missing)}')
        names = list(args.scenarios)
    if bt.ompl_available():
        bt.set_ompl_quiet(args.seed)
    elif not args.no_ompl:
        print('OMPL not importable: skipping OMPL', file=sys.stderr)
    bench = {'meta': {
        'date': dt.datetime.now().isoformat(timespec='seconds'), 'command': command,
        'machine': f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, '
                   f'Python {platform.python_version()}',
        'repeats': args.repeats, 'ws': args.ws, 'ompl_cap_s': args.ompl_cap,
        'ompl_planners': [] if args.no_ompl or not bt.ompl_available()
        else [OMPL_LABEL.get(p, p) for p in args.ompl_planners],
        'ompl_multipliers': list(MULTIPLIERS), 'grid_n': args.grid_n,
        'scenario_dir': str(args.scenario_dir)}, 'cases': []}
    todo = [(n, w) for n in names for w in args.ws]
    bar = tqdm(todo, desc='benchmark', unit='case', file=sys.stderr)
    scenario, grid = None, None
    for name, w in bar:
        bar.set_postfix_str(f'{name}@{w}')
        if scenario is None or scenario.name != name:
            scenario = load_scenario(args.scenario_dir / f'{name}.yaml')
            grid = bt.build_grid(scenario.threats, scenario.start, scenario.goal, scenario.box,
                                 args.grid_n) if args.grid_n > 1 else None
        ref = refs.get((name, round(w, 6)))
        if ref is None:
            continue
        bench['cases'].append(run_case(scenario, w, ref, args, grid))
        write_outputs(bench, args.out)
    print('\n' + summary_table(bench['cases']))
    return bench


if __name__ == '__main__':
    sys.exit(main())
