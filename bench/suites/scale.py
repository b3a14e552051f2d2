"""Scaling sweep of threat_planner's ``best`` method over the number of threats.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python -m bench scale                # N = 20 ... 10000, ~5 min
    .venv/bin/python -m bench scale --quick        # N <= 1000, 1 repeat
    .venv/bin/python -m bench benchmark --scale    # the benchmark, then this

For N = 20, 100, 300, 1000, 3000 and 10000 threats placed uniformly at random (fixed seed)
in a cube of side ``100 (N / 20)^(1/3)`` m, the density of the 20-threat scenarios, with
start and goal at opposite corners at mid height, and then for the shared
``scale1000.yaml`` and ``scale10000.yaml``, a fresh subprocess per problem and variant
runs ``plan`` (``best``, w = 0.5) ``--repeats`` times (fewer once the runs pass 10 s) on a
freshly built ``ThreatField``. The variants are ``best`` (the default, with the angle
limits) and ``best (no angle limits)`` (``max_pitch_deg=90, max_turn_deg=180``, the rules
OMPL and the grid floor play by). Each measurement reports:

* the median of each stage of ``PlanResult.timings_ms`` and of the wall time of ``plan``;
* the process's peak resident set size (``VmHWM``) and its growth over the baseline
  measured after imports and problem set-up;
* the peak of Python-heap allocations during one more ``plan`` under ``tracemalloc``
  (numpy's buffers included).

Writes ``scale.json``, ``scale.md`` and ``scale.png`` (log-log ms per stage and memory
against N) to ``bench/results/`` (``bench/results/quick/`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import statistics
import subprocess
import sys

from tqdm import tqdm

from bench.toolkit.cases import NO_ANGLE_LIMITS, scale_problem
from bench.toolkit.repo import RESULTS, SHARED, suite_process
from bench.toolkit.timing import peak_rss_mb

SIZES = (20, 100, 300, 1000, 3000, 10000)
QUICK_SIZES = (20, 100, 300, 1000)
FILES = ('scale1000', 'scale10000')
SEED = 7
W = 0.5
#: Variants measured: label -> PlannerConfig fields on top of method ``best``.
VARIANTS = {'best': {}, 'best (no angle limits)': NO_ANGLE_LIMITS}
#: Stop repeating a problem once its runs have taken this long [ms].
REPEAT_BUDGET_MS = 10_000.0


def worker(n: int | None, scenario: str | None, seed: int, repeats: int, w: float,
           variant: str = 'best') -> dict:
    """Measure one problem in this (fresh) process; return the measurements.

    Parameters
    ----------
    n : int or None
        Number of threats of a :func:`bench.toolkit.cases.scale_problem`, or None.
    scenario : str or None
        A scenario file instead.
    seed : int
        Seed of the generated problem.
    repeats : int
        Timed runs (median reported).
    w : float
        Threat weight.
    variant : str
        A key of :data:`VARIANTS`.

    Returns
    -------
    dict
        ``n``, ``name``, ``variant``, ``wall_ms``, ``timings_ms`` (median per stage), ``J``,
        ``side_m``, ``baseline_rss_mb``, ``peak_rss_mb``, ``rss_growth_mb``,
        ``tracemalloc_peak_mb``.
    """
    import gc
    import time
    import tracemalloc

    from threat_planner.core.planner import plan, PlannerConfig
    from threat_planner.core.inputs.scenario import load_scenario
    from threat_planner.core.world.threats import ThreatField

    if scenario:
        sc = load_scenario(scenario)
        field, start, goal, box, name = sc.threats, sc.start, sc.goal, sc.box, sc.name
    else:
        field, start, goal, box = scale_problem(n, seed)
        name = f'uniform N={n}'
    positions, intensities = field.positions.copy(), field.intensities.copy()
    config = PlannerConfig(w=w, method='best', **VARIANTS[variant])
    gc.collect()
    rss0 = peak_rss_mb()
    walls, stages, res = [], [], None
    for _ in range(repeats):
        fresh = ThreatField.from_arrays(positions, intensities)
        t0 = time.perf_counter()
        res = plan(fresh, start, goal, box, config)
        walls.append(1e3 * (time.perf_counter() - t0))
        stages.append(res.timings_ms)
        if sum(walls) > REPEAT_BUDGET_MS:
            break
    rss1 = peak_rss_mb()
    keys = list(dict.fromkeys(k for s in stages for k in s))
    j = float(res.cost.J)
    res_feasible = res.feasible
    del res
    gc.collect()
    fresh = ThreatField.from_arrays(positions, intensities)
    tracemalloc.start()
    plan(fresh, start, goal, box, config)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {'n': len(positions), 'name': name, 'variant': variant, 'w': w,
            'repeats': len(walls), 'feasible': bool(res_feasible),
            'wall_ms': statistics.median(walls), 'wall_runs_ms': walls,
            'timings_ms': {k: statistics.median(s.get(k, 0.0) for s in stages) for k in keys},
            'J': j, 'side_m': float(box.hi[0] - box.lo[0]),
            'baseline_rss_mb': rss0, 'peak_rss_mb': rss1, 'rss_growth_mb': rss1 - rss0,
            'tracemalloc_peak_mb': peak / 2 ** 20}


def _run_worker(extra: list[str], repeats: int, seed: int, w: float, variant: str) -> dict:
    cmd = suite_process('scale', '--worker', *extra, '--repeats', str(repeats),
                        '--seed', str(seed), '--w', str(w), '--variant', variant)
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f'worker {" ".join(extra)} failed:\n{proc.stderr[-2000:]}')
    return json.loads(proc.stdout.strip().splitlines()[-1])


STAGES = ('partition_ms', 'edge_costs_ms', 'search_ms', 'smoothing_ms', 'screening_ms',
          'optimisation_ms', 'total_ms')


def _stage_keys(rows: list[dict]) -> list[str]:
    keys = list(dict.fromkeys(k for r in rows for k in r['timings_ms']))
    return [k for k in STAGES if k in keys] + [k for k in keys if k not in STAGES]


def render_markdown(data: dict) -> str:
    """Render the ``scale.md`` report from the results."""
    rows = data['sizes'] + data['files']
    keys = _stage_keys(rows)
    head = ['problem', 'variant', 'N', 'side m', 'runs']
    head += [k.replace('_ms', ' ms') for k in keys]
    head += ['wall ms', 'J', 'feasible', 'peak RSS MiB', 'RSS growth MiB', 'tracemalloc peak MiB']
    lines = ['| ' + ' | '.join(head) + ' |', '|---|---|' + '---:|' * (len(head) - 2)]
    for r in rows:
        side = r.get('side_m')
        cells = [r['name'], r.get('variant', 'best'), str(r['n']),
                 f'{side:.0f}' if side else '-', str(r['repeats'])]
        cells += [f"{r['timings_ms'].get(k, 0.0):.1f}" for k in keys]
        cells += [f"{r['wall_ms']:.1f}", f"{r['J']:.2f}", str(r.get('feasible', '-')),
                  f"{r['peak_rss_mb']:.0f}",
                  f"{r['rss_growth_mb']:.0f}", f"{r['tracemalloc_peak_mb']:.1f}"]
        lines.append('| ' + ' | '.join(cells) + ' |')
    text = (
        f"`best` (w = {data['w']}) as the default (angle limits on) and with "
        '`max_pitch_deg=90, max_turn_deg=180` (no angle limits, the rules of OMPL and the '
        f"grid floor); N threats uniform at random (seed {data['seed']}) in a "
        "cube of side 100 (N/20)^(1/3) m (the 20-threat scenarios' density), start and goal "
        'at opposite corners at mid height; then the shared scale1000.yaml and '
        'scale10000.yaml. Stage times are `PlanResult.timings_ms`, median of up to '
        f"{data['repeats']} runs (fewer, see column runs, once they pass 10 s); wall ms is the "
        'whole `plan` call on a freshly built ThreatField (it adds input checks and the k-d '
        'tree). Each problem runs in a fresh subprocess: peak RSS is its high-water mark '
        '(VmHWM; interpreter and libraries included), RSS growth is that over the baseline '
        'after imports and set-up, and the tracemalloc peak is the Python-heap peak (numpy '
        'buffers included) of one more plan.')
    return '\n'.join([
        '# Scaling', '', text, '',
        '\n'.join(lines), '', '![time and memory against N](scale.png)', ''])


def plot(data: dict, path: Path) -> None:
    """Plot (log-log) ms per stage and memory against N."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    every = sorted(data['sizes'], key=lambda r: r['n'])
    rows = [r for r in every if r.get('variant', 'best') == 'best']
    n = [r['n'] for r in rows]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    for k in _stage_keys(rows):
        y = [max(r['timings_ms'].get(k, 0.0), 1e-3) for r in rows]
        ax.plot(n, y, 'o-', lw=2.5 if k == 'total_ms' else 1.2, label=k.replace('_ms', ''))
    free = [r for r in every if r.get('variant') == 'best (no angle limits)']
    if free:
        ax.plot([r['n'] for r in free], [r['timings_ms']['total_ms'] for r in free], 'k--',
                lw=1.5, label='total, no angle limits')
    for f in data['files']:
        ax.plot([f['n']], [f['timings_ms']['total_ms']],
                'k*' if f.get('variant', 'best') == 'best' else 'kx', ms=12)
    ax.plot([], [], 'k*', label='total, scale*.yaml')
    ax.plot([], [], 'kx', label='total, scale*.yaml, no angle limits')
    for target_n, ms in ((20, 20.0), (1000, 300.0), (10000, 3000.0)):
        ax.plot([target_n], [ms], 'rv', ms=9)
    ax.plot([], [], 'rv', label='target')
    ax.set(xscale='log', yscale='log', xlabel='threats N', ylabel='ms',
           title='time per stage (best, w = %.1f; lines: default limits)' % data['w'])
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8)
    ax2.plot(n, [r['peak_rss_mb'] for r in rows], 'o-', label='peak RSS (process)')
    ax2.plot(n, [max(r['rss_growth_mb'], 1e-1) for r in rows], 's-', label='RSS growth')
    ax2.plot(n, [r['tracemalloc_peak_mb'] for r in rows], '^-', label='tracemalloc peak')
    ax2.axhline(1024.0, color='r', ls='--', label='1 GiB target')
    ax2.set(xscale='log', yscale='log', xlabel='threats N', ylabel='MiB', title='memory')
    ax2.grid(True, which='both', alpha=0.3)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep (or, with ``--worker``, one measurement) and write the outputs."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--quick', action='store_true', help='N <= 1000, 1 repeat, no 10k file')
    p.add_argument('--sizes', nargs='+', type=int, help=f'threat counts (default {SIZES})')
    p.add_argument('--repeats', type=int, help='timed runs per problem (default 3, quick 1)')
    p.add_argument('--seed', type=int, default=SEED)
    p.add_argument('--w', type=float, default=W)
    p.add_argument('--scenario-dir', type=Path, default=SHARED)
    p.add_argument('--out', type=Path, help='output directory (default bench/results)')
    p.add_argument('--worker', action='store_true', help=argparse.SUPPRESS)
    p.add_argument('--n', type=int, help=argparse.SUPPRESS)
    p.add_argument('--file', help=argparse.SUPPRESS)
    p.add_argument('--variant', default='best', choices=list(VARIANTS), help=argparse.SUPPRESS)
    p.add_argument('--variants', nargs='+', choices=list(VARIANTS), default=list(VARIANTS),
                   help='variants to measure (default: all)')
    args = p.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    if args.worker:
        out = worker(args.n, args.file, args.seed, repeats, args.w, args.variant)
        print(json.dumps(out))
        return 0
    sizes = args.sizes or (QUICK_SIZES if args.quick else SIZES)
    files = [f for f in (FILES[:1] if args.quick else FILES)
             if (args.scenario_dir / f'{f}.yaml').exists()]
    out = args.out or (RESULTS / 'quick' if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    data = {'seed': args.seed, 'w': args.w, 'repeats': repeats, 'sizes': [], 'files': []}
    jobs = [(k, x, v) for k, xs in (('n', sizes), ('file', files)) for x in xs
            for v in args.variants]
    for kind, what, variant in tqdm(jobs, desc='scale', unit='problem', file=sys.stderr):
        if kind == 'n':
            r = _run_worker(['--n', str(what)], repeats, args.seed, args.w, variant)
            data['sizes'].append(r)
        else:
            r = _run_worker(['--file', str(args.scenario_dir / f'{what}.yaml')], repeats,
                            args.seed, args.w, variant)
            r['name'] = what
            data['files'].append(r)
        (out / 'scale.json').write_text(json.dumps(data, indent=1))
    (out / 'scale.md').write_text(render_markdown(data))
    plot(data, out / 'scale.png')
    print(render_markdown(data).split('\n\n')[2])
    return 0
