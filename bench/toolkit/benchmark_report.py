"""Tables, targets, plot and result files of ``python -m bench benchmark``.

Every row states its rules: whether its path stays in the flight box and which limits it
is held to. Ratios are to the in-box yardstick (limits off) of the case; the limits-on row
is also compared with the limited yardstick; ``reference.json`` appears only as a lower
bound (its unbounded paths leave the box). ``benchmark.json`` is strict JSON: inf and nan
are written as null and read back by :func:`load_json`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
import statistics

from bench.toolkit.repo import RESULTS

#: Labels of our variants.
OFF = 'best (limits off)'
ON = 'best (limits on)'
#: Targets of issue 11.
MEDIAN_IN_BOX = 1.002
WORST_IN_BOX = 1.02
WORST_LIMITED = 1.01
MS_20_MEDIAN = 15.0
MS_20_WORST = 40.0
MS_1000 = 250.0
MS_10000 = 1500.0
MEM_10000_MIB = 500.0
CLI_RATIO = 8.0
#: Rules of each row (stays in the box, limits), by label or label prefix.
RULES = {'paper': ('yes', "paper's per-vertex 45 deg pitch / 60 deg turn"),
         'improved': ('yes', "paper's per-vertex 45 deg pitch / 60 deg turn"),
         OFF: ('yes', 'none'), ON: ('yes', 'climb/dive/turn radius of the limited yardstick'),
         'straight line': ('yes', 'none'), 'grid': ('yes', 'none'), 'OMPL': ('yes', 'none')}


def rules(label: str) -> tuple[str, str]:
    """Return (stays in the box, limits) of a row."""
    if label in RULES:
        return RULES[label]
    return RULES['grid'] if label.startswith('grid') else RULES['OMPL']


def median(xs) -> float:
    """Median of the finite values (nan if none)."""
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return statistics.median(xs) if xs else math.nan


def _worst(xs) -> float:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return max(xs) if xs else math.nan


def _f(x, fmt: str = '.4f') -> str:
    return '-' if x is None or not math.isfinite(x) else format(x, fmt)


def _ms(ms: float) -> str:
    return f'{ms:.0f}' if ms >= 10 else f'{ms:.1f}'


def labels_of(cases: list[dict]) -> list[str]:
    """Every row label, first-seen order."""
    out: list[str] = []
    for c in cases:
        out += [k for k in c['methods'] if k not in out]
    return out


def summary_table(cases: list[dict]) -> str:
    """One row per method: rules, J / in-box yardstick, time, paths in the box."""
    lines = ['| method | in box | limits | cases | median J/in-box | worst J/in-box '
             '| median J/limited | worst J/limited | median ms | paths in the box |',
             '|---|---|---|---:|---:|---:|---:|---:|---:|---:|']
    for label in labels_of(cases):
        ms = [c['methods'][label] for c in cases if label in c['methods']]
        box, limits = rules(label)
        inside = sum(bool(m.get('in_box')) for m in ms)
        lines.append(
            f"| {label} | {box} | {limits} | {len(ms)} | {_f(median(m['ratio'] for m in ms))} "
            f"| {_f(_worst(m['ratio'] for m in ms))} "
            f"| {_f(median(m.get('ratio_limited') for m in ms))} "
            f"| {_f(_worst(m.get('ratio_limited') for m in ms))} "
            f"| {_ms(median(m['ms'] for m in ms))} | {inside}/{len(ms)} |")
    lb = [c['yardsticks']['lower_bound'] / c['yardsticks']['in_box'] for c in cases
          if c['yardsticks']['in_box'] and c['yardsticks']['lower_bound']]
    least = min(lb) if lb else math.nan
    lines.append(f'| lower bound `reference.json` (leaves the box) | no | none | {len(lb)} '
                 f'| {_f(median(lb))} | {_f(least)} (least) | - | - | - | 0 (a bound only) |')
    return '\n'.join(lines)


def cases_table(cases: list[dict]) -> str:
    """Per case: both yardsticks, the lower bound, and our rows' J (ratio) and ms."""
    head = ['scenario', 'w', 'N', 'in-box yardstick J (source)', 'bench / reference_box',
            'limited yardstick J', 'limits C/D/R', 'lower bound', 'paper J (ratio)',
            'improved J (ratio)', f'{OFF} J (ratio)', 'ms', f'{ON} J (/limited)', 'ms',
            'feasible', 'grid J (ratio)']
    lines = ['| ' + ' | '.join(head) + ' |', '|---|---|---|' + '---:|' * (len(head) - 3)]
    for c in cases:
        y, m = c['yardsticks'], c['methods']
        grid = next((v for k, v in m.items() if k.startswith('grid')), None)
        lim = y.get('limits')

        def cell(v, key='ratio'):
            return '-' if not v else f"{v['J']:.2f} ({_f(v.get(key))})"
        on = m.get(ON)
        lines.append('| ' + ' | '.join([
            c['scenario'], f"{c['w']:.1f}", str(c['n_threats']),
            f"{_f(y['in_box'], '.2f')} ({y['in_box_source']})", _f(y['box_check'], '.5f'),
            _f(y['limited'], '.2f'),
            '-' if not lim else f"{lim['max_climb_deg']:g}/{lim['max_dive_deg']:g}/"
                                f"{lim['min_turn_radius_m']:g}",
            _f(y['lower_bound'], '.2f'), cell(m.get('paper')), cell(m.get('improved')),
            cell(m.get(OFF)), _ms(m[OFF]['ms']) if OFF in m else '-',
            cell(on, 'ratio_limited'), _ms(on['ms']) if on else '-',
            '-' if not on else ('yes' if on['limits_ok'] else f"NO ({on['worst_violation']})"),
            cell(grid)]) + ' |')
    return '\n'.join(lines)


def ompl_table(cases: list[dict]) -> str:
    """OMPL against ``best (limits off)`` (same rules: in the box, no limits)."""
    labs = [k for k in labels_of(cases) if '@' in k]
    if not labs:
        return '_OMPL not run._'
    head = ['scenario', 'w', f'{OFF} J (ratio)']
    for lab in labs:
        head += [f'{lab} J (ratio)', 'budget s']
    lines = ['| ' + ' | '.join(head) + ' |', '|---|---|' + '---:|' * (len(head) - 2)]
    for c in cases:
        m = c['methods']
        row = [c['scenario'], f"{c['w']:.1f}",
               f"{m[OFF]['J']:.2f} ({_f(m[OFF]['ratio'])})" if OFF in m else '-']
        for lab in labs:
            v = m.get(lab)
            row += ['-', '-'] if not v else [
                f"{v['J']:.2f} ({_f(v['ratio'])})",
                f"{v['budget_s']:.2f}{' (cap)' if v['capped'] else ''}"]
        lines.append('| ' + ' | '.join(row) + ' |')
    return '\n'.join(lines)


def evaluate_targets(cases: list[dict], speed: dict | None = None) -> list[dict]:
    """Every target of issue 11 with its value, verdict and what it was measured on."""
    rows: list[dict] = []

    def add(name: str, value: float, limit: float, note: str, ok: bool | None = None) -> None:
        if ok is None:
            ok = None if not math.isfinite(value) else value <= limit
        rows.append({'target': name, 'value': value, 'limit': limit,
                     'verdict': 'n/a' if ok is None else ('PASS' if ok else 'MISS'),
                     'note': note})

    off = [(c, c['methods'][OFF]) for c in cases if OFF in c['methods']]
    ratios = [m['ratio'] for _, m in off]
    n_y = sum(math.isfinite(r) for r in ratios)
    where = max(off, key=lambda cm: cm[1]['ratio'] if math.isfinite(cm[1]['ratio']) else -1,
                default=None)
    worst_at = f"; worst at {where[0]['scenario']}@{where[0]['w']}" if where else ''
    add(f'{OFF}: median J / in-box yardstick <= {MEDIAN_IN_BOX}', median(ratios),
        MEDIAN_IN_BOX, f'{n_y} of {len(off)} cases have an in-box yardstick')
    add(f'{OFF}: worst J / in-box yardstick <= {WORST_IN_BOX}', _worst(ratios), WORST_IN_BOX,
        f'{n_y} cases{worst_at}')
    on = [c['methods'][ON] for c in cases if ON in c['methods']]
    if on:
        bad = sum(not m['limits_ok'] for m in on)
        add(f'{ON}: feasible (in the box, within the limits) on every case', bad, 0,
            f'value: infeasible cases of {len(on)} (independent check, '
            'bench/toolkit/flight_limits.py)')
        lim = [m['ratio_limited'] for m in on]
        n_l = sum(math.isfinite(x) for x in lim)
        add(f'{ON}: worst J / limited yardstick <= {WORST_LIMITED}', _worst(lim),
            WORST_LIMITED, f'{n_l} of {len(on)} cases have a limited yardstick')
        small = [c['methods'][ON]['ms'] for c in cases
                 if ON in c['methods'] and c['n_threats'] <= 24]
        add(f'{ON}: ~20 threats median <= {MS_20_MEDIAN:g} ms', median(small), MS_20_MEDIAN,
            f'{len(small)} benchmark cases with 16-24 threats, wall of plan()')
        add(f'{ON}: ~20 threats worst <= {MS_20_WORST:g} ms', _worst(small), MS_20_WORST,
            'same cases')
    rrt = [(c, c['methods']['RRT*@10x']) for c in cases
           if 'RRT*@10x' in c['methods'] and OFF in c['methods']]
    if rrt:
        worst = max(c['methods'][OFF]['J'] / r['J'] for c, r in rrt)
        wins = sum(c['methods'][OFF]['J'] < r['J'] for c, r in rrt)
        add(f'{OFF} J < RRT*@10x J on every case', worst, 1.0,
            f'{wins}/{len(rrt)} cases; value: worst ours / RRT*', ok=wins == len(rrt))
    runs = [m for c in cases for k, m in c['methods'].items() if '@' in k]
    if runs:
        worst = _worst([m['rel_diff'] for m in runs] or [math.inf])
        add('check: OMPL cost of its path == path_cost J (rel <= 1e-6)', worst, 1e-6,
            f'{len(runs)} runs')
    for key, name, limit in (('plan_1000_ms', f'{ON}: 1,000 threats plan() <= 250 ms',
                              MS_1000),
                             ('plan_10000_ms', f'{ON}: 10,000 threats plan() <= 1.5 s',
                              MS_10000),
                             ('rss_10000_mib', f'10,000 threats: peak memory < '
                              f'{MEM_10000_MIB:g} MiB', MEM_10000_MIB),
                             ('cli_ratio', f'threat-planner plan, 10,000-threat YAML <= '
                              f'{CLI_RATIO:g}x bare Delaunay', CLI_RATIO)):
        value = (speed or {}).get(key, math.nan)
        add(name, value, limit, (speed or {}).get(key + '_note', 'not measured'))
    return rows


def targets_table(rows: list[dict]) -> str:
    """Markdown table of the targets."""
    lines = ['| target | value | verdict | measured on |', '|---|---:|---|---|']
    lines += [f"| {r['target']} | {r['value']:.5g} | **{r['verdict']}** | {r['note']} |"
              for r in rows]
    return '\n'.join(lines)


def render_markdown(bench: dict, speed_md: str | None) -> str:
    """Return the whole ``benchmark.md``."""
    cases, meta = bench['cases'], bench['meta']
    speed = bench.get('speed')
    parts = [
        '# Benchmark', '',
        f"Generated {meta['date']} by `{meta['command']}` on {meta['machine']}, a machine "
        'shared with other engineers\' jobs: times are indicative, compare rows of this run '
        'only.' + (f" Ratios re-scored {meta['rescored']} against the yardsticks of that "
                   'time (`--rescore`: same paths, more yardsticks).'
                   if meta.get('rescored') else ''), '',
        '**Rules.** Every J is the library\'s exact closed-form `path_cost` of the row\'s '
        'final path. Every row\'s path is held inside the flight box (column "paths in the '
        'box" counts it, to 1e-6 of the diagonal). The primary yardstick is the **in-box '
        'yardstick** (limits off): the bench\'s own (`bench/toolkit/yardstick.py`, cached in '
        '`bench/results/yardstick.json`, 41^3 grid; see `yardstick.md`), or where the bench '
        'has no value `reference_box.json` (same recipe, computed elsewhere); where both '
        'exist their ratio is shown ("bench / reference_box"). `best (limits on)` is run with '
        'the **limited yardstick\'s** climb / dive / turn-radius limits (C/D/R) and compared '
        'with it; its feasibility is checked by the bench\'s independent '
        '`flight_limits.check_limits`. `paper` and `improved` are held to the paper\'s '
        'per-vertex 45 deg pitch / 60 deg turn check (their J is still compared with the '
        'in-box yardstick). `reference.json` (unbounded L-BFGS, paths leave the box) is only '
        'a labelled lower bound. Stored yardstick paths are re-scored and checked inside the '
        'box on loading.', '',
        f"OMPL ({', '.join(meta['ompl_planners']) or 'not run'}) plans in the box on the same "
        'J (closed-form `motionCost`), budgets 10x and 100x our `best (limits off)` time, '
        f"capped at {meta['ompl_cap_s']:g} s. The grid floor is Dijkstra on a "
        f"{meta['grid_n']}^3 26-connected grid with exact edge J.", '',
        '## Summary', '', summary_table(cases), '',
        '## Targets', '', targets_table(evaluate_targets(cases, speed)), '',
        '## Per case', '', cases_table(cases), '',
        '## OMPL at 10x and 100x our time (in the box, no limits)', '', ompl_table(cases), '',
        '![J / in-box yardstick against time](benchmark.png)', '']
    if speed_md:
        parts += ['## Speed (from `bench/results/speed.md`)', '', speed_md, '']
    return '\n'.join(parts)


def plot(cases: list[dict], path: Path) -> None:
    """J / in-box yardstick against time per row, log axes."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9, 6))
    cmap = plt.get_cmap('tab10')
    for i, lab in enumerate(labels_of(cases)):
        pts = [(c['methods'][lab]['ms'] / 1e3, c['methods'][lab]['ratio']) for c in cases
               if lab in c['methods'] and math.isfinite(c['methods'][lab]['ratio'])
               and c['methods'][lab]['ms'] > 0]
        if pts:
            x, y = zip(*pts)
            ax.scatter(x, y, s=28, marker='osD^v<>phX*P'[i % 12], color=cmap(i % 10),
                       label=lab, alpha=0.8)
    ax.axhline(1.0, color='k', lw=0.8, ls='--')
    ax.set_xscale('log')
    ax.set_yscale('log')
    ax.set_xlabel('wall time per plan [s] (log)')
    ax.set_ylabel('J / in-box yardstick J (log)')
    ax.set_title('J ratio to the in-box yardstick against time, every scenario and w')
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
        for k in ('ratio', 'rel_diff', 'ratio_limited'):
            if k in out and out[k] is None:
                out[k] = math.nan
        return out
    if isinstance(obj, list):
        return [_unclean(v) for v in obj]
    return obj


def load_json(path: Path) -> dict | None:
    """Read a ``benchmark.json`` written by :func:`write_outputs`, or None if absent."""
    return _unclean(json.loads(path.read_text())) if path.exists() else None


def write_outputs(bench: dict, out: Path) -> None:
    """Write benchmark.json, benchmark.md and benchmark.png."""
    out.mkdir(parents=True, exist_ok=True)
    (out / 'benchmark.json').write_text(json.dumps(_clean(bench), indent=1))
    speed_md = RESULTS / 'speed.md'
    (out / 'benchmark.md').write_text(render_markdown(
        bench, speed_md.read_text() if speed_md.exists() else None))
    if bench['cases']:
        plot(bench['cases'], out / 'benchmark.png')
