"""``report.md`` of a study: J against w per scenario, and the spread of J under uncertainty.

Tables in Markdown beside two figures (``j_vs_w.png``; ``spread.png`` with uncertainty),
all read from the merged results table.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
import statistics

import numpy as np

from threat_planner.batch.study import Study

__all__ = ['write_report']

REPORT = 'report.md'
#: Scenarios drawn in the figures at most (the tables hold every one).
FIGURE_SCENARIOS = 12
#: Most lines of a J-against-w panel that get a legend; more are drawn without one.
LEGEND_LINES = 8


def _fmt(v: float | None) -> str:
    return '-' if v is None or not np.isfinite(v) else f'{v:.4g}'


def _combo(row: dict, names: list[str]) -> str:
    parts = [row['method']] + [f'{n}={row[n]:g}' if isinstance(row[n], float)
                               else f'{n}={row[n]}' for n in names]
    return ', '.join(parts)


def write_report(out: Path, table, study: Study) -> Path:
    """Write ``out/report.md`` (and its figures) from the results table; return its path."""
    names = [n for n, _ in study.settings]
    rows = table.drop_columns(['path']).to_pylist()
    plans = [r for r in rows if r['sample'] is None]
    s = study.sampling
    lines = [f'# Study {study.path.name}', '',
             f'`{study.path}`: {len(study.scenarios)} scenarios, w {list(study.w)}, method '
             f'{list(study.methods)}'
             + ''.join(f', {n} {list(v)}' for n, v in study.settings) + '.']
    if s is not None:
        lines.append(f'Uncertainty: {s.samples} evaluation pictures, threat positions moved '
                     f'by N(0, {s.position_sigma_m:g} m) per axis, intensities scaled by '
                     f'lognormal(0, {s.intensity_sigma:g}), seed {s.seed}'
                     + (f'; robust plans over {s.robust_samples} other pictures.'
                        if s.robust_samples else '.'))
    ok = [r for r in plans if r['error'] is None]
    times = [r['total_ms'] for r in ok]
    lines += ['', f'{len(plans)} plans ({len(rows)} rows): {len(plans) - len(ok)} refused by '
              f'the planner, {sum(not r["feasible"] for r in ok)} infeasible (marked *). '
              + (f'Plan time: median {statistics.median(times):.1f} ms, total '
                 f'{sum(times) / 1e3:.1f} s.' if times else ''), '']
    lines += _j_table(plans, names, study)
    figure = _plot_j(out, plans, names, study)
    if figure:
        lines += ['', f'![J against w]({figure})', '']
    if s is not None:
        lines += _spread(out, rows, names, study)
    refused = [r for r in plans if r['error'] is not None]
    if refused:
        lines += ['## Refused plans', '', '| scenario | w | combination | plan | error |',
                  '|---|---|---|---|---|']
        lines += [f"| {r['scenario']} | {r['w']:g} | {_combo(r, names)} | {r['plan']} | "
                  f"{r['error']} |" for r in refused]
    path = out / REPORT
    path.write_text('\n'.join(lines) + '\n')
    return path


def _j_table(plans: list[dict], names: list[str], study: Study) -> list[str]:
    cells: dict[tuple, dict[float, str]] = defaultdict(dict)
    for r in plans:
        mark = '' if r['error'] is not None or r['feasible'] else '*'
        cells[(r['scenario'], _combo(r, names), r['plan'])][r['w']] = _fmt(r['J']) + mark
    head = ['## J against w', '', '| scenario | combination | plan | '
            + ' | '.join(f'w={w:g}' for w in study.w) + ' |',
            '|---|---|---|' + '---|' * len(study.w)]
    return head + [f'| {sc} | {combo} | {plan} | '
                   + ' | '.join(by_w.get(w, '') for w in study.w) + ' |'
                   for (sc, combo, plan), by_w in cells.items()]


def _figure_scenarios(study: Study) -> list[str]:
    return [sc.key for sc in study.scenarios[:FIGURE_SCENARIOS]]


def _grid(n: int):
    """Return a figure of n panels, three a row, and its axes (no pyplot: 1.1 s to import)."""
    from matplotlib.figure import Figure
    cols = min(3, n)
    rows = -(-n // cols)
    fig = Figure(figsize=(4.2 * cols, 3.2 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return fig, axes.flat


def _plot_j(out: Path, plans: list[dict], names: list[str], study: Study) -> str:
    keys = _figure_scenarios(study)
    if not keys or len(study.w) < 2:
        return ''
    fig, axes = _grid(len(keys))
    for ax, key in zip(axes, keys):
        lines: dict[str, list] = defaultdict(list)
        for r in plans:
            if r['scenario'] == key and r['J'] is not None:
                lines[f"{_combo(r, names)}, {r['plan']}"].append((r['w'], r['J']))
        for label, pts in lines.items():
            ax.plot(*zip(*sorted(pts)), marker='o', markersize=3, label=label)
        ax.set_title(Path(key).name, fontsize=9)
        ax.set_xlabel('w')
        ax.set_ylabel('J on the nominal picture')
        if len(lines) <= LEGEND_LINES:
            # A fixed corner: 'best' searches the panel's data for every entry (0.66 s of
            # a 1,000-plan study's 1.1 s report).
            ax.legend(fontsize=6, loc='upper left')
        else:
            ax.text(0.02, 0.98, f'{len(lines)} combinations, one line each', fontsize=6,
                    va='top', transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(out / 'j_vs_w.png', dpi=100)
    return 'j_vs_w.png'


def _spread(out: Path, rows: list[dict], names: list[str], study: Study) -> list[str]:
    groups: dict[tuple, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r['sample'] is not None and r['J'] is not None:
            groups[(r['scenario'], r['w'], _combo(r, names))][r['plan']].append(r['J'])
    robust = study.sampling.robust_samples > 0
    head = ['## J under uncertainty', '',
            'Mean, 5th and 95th percentile of J over the evaluation pictures'
            + (', and the robust plan\'s mean against the nominal plan\'s.' if robust
               else '.'), '',
            '| scenario | w | combination | nominal mean | p5 | p95 |'
            + (' robust mean | p5 | p95 | robust vs nominal |' if robust else ''),
            '|---|---|---|---|---|---|' + ('---|---|---|---|' if robust else '')]
    body = []
    for (sc, w, combo), by_plan in groups.items():
        cells = []
        for plan in ('nominal', 'robust') if robust else ('nominal',):
            js = by_plan.get(plan)
            cells += ([_fmt(float(np.mean(js))), _fmt(float(np.percentile(js, 5))),
                       _fmt(float(np.percentile(js, 95)))] if js else ['-'] * 3)
        if robust:
            n, r = by_plan.get('nominal'), by_plan.get('robust')
            cells.append(f'{100 * (np.mean(r) / np.mean(n) - 1):+.2f} %' if n and r else '-')
        body.append(f'| {sc} | {w:g} | {combo} | ' + ' | '.join(cells) + ' |')
    figure = _plot_spread(out, groups, study)
    return head + body + ([''] + [f'![spread of J]({figure})'] if figure else []) + ['']


def _plot_spread(out: Path, groups: dict, study: Study) -> str:
    keys = [k for k in _figure_scenarios(study) if any(g[0] == k for g in groups)]
    if not keys:
        return ''
    fig, axes = _grid(len(keys))
    colours = {'nominal': 'tab:blue', 'robust': 'tab:orange'}
    for ax, key in zip(axes, keys):
        data, labels, colour = [], [], []
        for (sc, w, combo), by_plan in groups.items():
            if sc != key:
                continue
            for plan, js in by_plan.items():
                data.append(js)
                labels.append(f'w={w:g}\n{plan[0]}')
                colour.append(colours[plan])
        box = ax.boxplot(data, patch_artist=True, showfliers=False, showmeans=True)
        for patch, c in zip(box['boxes'], colour):
            patch.set_facecolor(c)
        ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=6)
        ax.set_title(f'{Path(key).name} (n nominal, r robust; triangle: mean)', fontsize=9)
        ax.set_ylabel('J on the evaluation pictures')
    fig.tight_layout()
    fig.savefig(out / 'spread.png', dpi=100)
    return 'spread.png'
