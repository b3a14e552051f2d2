"""Reproduction of the paper's Section IV on a scenario: Tables I-III, Case 3, figures.

And issue 43's detection table: the paper-cost plan against the detection-cost plan.

Node ids in the tables are this project's 0-based network ids (the paper numbers its own
network from 1; networks of different threat sets are not comparable id by id).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from threat_planner.cli.figures import plot_plan
from threat_planner.core.cost.kernels import path_cost
from threat_planner.core.inputs.scenario import Scenario
from threat_planner.core.planner import K_SWEEP, plan, PlannerConfig

W_SWEEP = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


def _table(header: list[str], rows: list[list[object]]) -> str:
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(str(c) for c in row) + ' |' for row in rows]
    return '\n'.join(lines)


def _how(config: PlannerConfig) -> str:
    """How the network and the entry/exit candidates of Table I were made, in words."""
    net = ("the paper's network: Delaunay cells of the threat positions only (their convex "
           'hull); start and goal join the nearest nodes' if config.network == 'threats' else
           'threats plus a lattice on the flight box surface (grown by 2 % of its diagonal), '
           'so the network covers the whole box; margin nodes are projected onto the box')
    if config.candidates == 'spread':
        cand = (f'the space around the start-goal axis is cut into K = '
                f'{config.entry_candidates} equal sectors (the first one upwards) and each '
                'sector gives its node nearest the start (exit: nearest the goal), among '
                'nodes ahead (towards the other end) whose cell has a threat vertex, so the '
                "flat all-lattice slivers of the box margin are left out; the paper's Fig. 11 "
                'picks nodes spread around S "by eye" the same way')
    else:
        cand = f'the K = {config.entry_candidates} nodes nearest the start (exit: the goal)'
    return (f'Network: {net}.\n\nEntry/exit candidates (Table I, II): {cand}. Cells with '
            'equal J are routes that the mass-spring smoothing at k = 1000 brings to the same '
            'rest state (the same side of every threat).')


#: The detection plan's weight w in its objective w H + (1 - w) L / L_0. H is about 1e-3 on
#: the paper's fields while L / L_0 is about 1, so at the paper's w = 0.5 the objective is
#: nearly all length and the detection plan trades detection for length; 0.999 makes the
#: two terms comparable.
DETECTION_W = 0.999

DETECTION_FOOTNOTE = (
    f'The paper-cost plan is method best at the paper\'s w (its J minimised); the detection '
    f'plan is method best with cost detection at w = {DETECTION_W:g}, minimising '
    f'w H + (1 - w) L / L_0 (L_0 the straight-line distance). J is the paper\'s cost of each '
    f'path at the paper\'s w; the objective column is at w = {DETECTION_W:g} for both. '
    '[1] Not the paper\'s w = 0.5: H is about 1e-3 on these fields while L / L_0 is about '
    '1, so at w = 0.5 the objective is almost all length and the detection plan trades '
    'detection for length (a shorter path with a higher P_detect).')


def detection_rows(scenario: Scenario, config: PlannerConfig = PlannerConfig(),
                   w_detection: float = DETECTION_W) -> list[dict]:
    """Plan a field with the paper cost and with the detection cost, side by side (issue 43).

    The paper-cost plan is method best at ``config.w``; the detection plan is method best
    with ``cost_model='detection'`` at ``w_detection``; both under the config's radar model
    and the scenario's airspace. Each row: ``cost`` ('paper' or 'detection'), ``w`` (the
    weight it was planned at), ``P_detect``, ``H``, ``length_m``, ``J`` (the paper's cost of
    the path at ``config.w``), ``objective`` (w H + (1 - w) L / L_0 at ``w_detection``,
    the detection plan's objective, for both), ``status`` (a bound's status, '' for none).
    """
    th, s, g, box = scenario.threats, scenario.start, scenario.goal, scenario.box
    l0 = float(np.linalg.norm(np.asarray(g, float) - np.asarray(s, float)))
    rows = []
    for cost, w in (('paper', config.w), ('detection', w_detection)):
        r = plan(th, s, g, box, replace(config, method='best', cost_model=cost, w=w),
                 airspace=scenario.airspace or None)
        d = r.detection
        length = float(np.linalg.norm(np.diff(r.path, axis=0), axis=1).sum())
        j = float(path_cost(r.path, th.positions, th.intensities, config.w).J)
        rows.append({'cost': cost, 'w': float(w), 'P_detect': float(d.p_detect),
                     'H': float(d.hazard), 'length_m': length, 'J': j,
                     'objective': w_detection * float(d.hazard)
                     + (1 - w_detection) * length / l0,
                     'status': r.detection_status})
    return rows


def detection_table(scenario: Scenario, config: PlannerConfig = PlannerConfig(),
                    w_detection: float = DETECTION_W) -> str:
    """Return the Markdown table of :func:`detection_rows`, the P_detect change, a footnote."""
    rows = detection_rows(scenario, config, w_detection)
    paper_p = rows[0]['P_detect']
    body = []
    for row in rows:
        change = ('' if row['cost'] == 'paper' or paper_p <= 0 else
                  f"{100 * (row['P_detect'] - paper_p) / paper_p:+.1f} %")
        w = f"{row['w']:g}" + (' [1]' if row['cost'] == 'detection' else '')
        body.append([row['cost'], w, f"{row['P_detect']:.4g}", f"{row['H']:.4g}",
                     f"{row['length_m']:.1f}", f"{row['J']:.1f}", f"{row['objective']:.6g}",
                     change, row['status'] or '-'])
    return _table(['cost minimised', 'w', 'P_detect', 'H', 'length [m]',
                   f'J (w={config.w:g})', f'w H + (1 - w) L / L_0 (w={w_detection:g})',
                   'P_detect vs paper', 'bound'], body) + '\n\n' + DETECTION_FOOTNOTE + (
        detection_warning(rows))


def detection_warning(rows: list[dict]) -> str:
    """Return a sentence when the detection plan does worse on its own objective than the paper's.

    Then the detection optimiser stopped in a worse basin than the paper-cost path offers
    (its warm start is method best's plan at its own w): the table says so rather than let
    the comparison pass for the optimum. ``''`` otherwise.
    """
    by = {row['cost']: row for row in rows}
    paper, det = by.get('paper'), by.get('detection')
    if paper is None or det is None or not det['objective'] > paper['objective'] * (1 + 1e-9):
        return ''
    return (f"\n\nNote: the detection plan's objective {det['objective']:.6g} is above the "
            f"paper-cost path's {paper['objective']:.6g} on the same objective: the detection "
            'optimiser stopped in a worse basin here, so this P_detect is not the least '
            'one available.')


def reproduce(scenario: Scenario, out_dir: str | Path, config: PlannerConfig = PlannerConfig(),
              progress: Callable[[str], None] | None = None) -> dict[str, str]:
    """Run the paper's experiments on a scenario and write tables and figures.

    Args:
        scenario: The scenario.
        out_dir: Folder for ``tables.md`` and the PNG figures.
        config: Base settings (k, limits, n_points, K); w and method are swept.
        progress: Called with a short label before each experiment step.

    Returns:
        ``{table name: Markdown text}``; the same text is in ``out_dir/tables.md``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    th, s, g, box = scenario.threats, scenario.start, scenario.goal, scenario.box
    tick = progress or (lambda label: None)
    base = replace(config, k=1000.0, auto_k=False)

    # Table I: J of every entry x exit candidate pair at w = 0.5, k = 1000 (Case 1).
    tick('Table I')
    r = plan(th, s, g, box, replace(base, w=0.5, method='improved'))
    entries = sorted({e for e, _ in r.candidates})
    exits = sorted({x for _, x in r.candidates})
    table1 = _table(['entry \\ exit'] + [f'exit via {x}' for x in exits],
                    [[e] + [f'{r.candidates.get((e, x), float("nan")):.1f}' for x in exits]
                     for e in entries])

    rows2, rows3, rows_k = [], [], []
    for w in W_SWEEP:
        tick(f'Tables II-III, Case 3 at w={w}')
        cfg = replace(base, w=w)
        imp = plan(th, s, g, box, replace(cfg, method='improved'))
        best_pair = min(imp.candidates, key=imp.candidates.get)
        rows2.append([w, best_pair[0], best_pair[1], f'{imp.candidates[best_pair]:.1f}'])
        former = plan(th, s, g, box, replace(cfg, method='paper'))
        rows3.append([w, '-'.join(map(str, former.node_sequence)),
                      '-'.join(map(str, imp.node_sequence)),
                      'same' if former.node_sequence == imp.node_sequence else 'differs'])
        feasible = {k: j for k, j in imp.k_sweep.items() if np.isfinite(j)}
        if feasible:
            k_best = min(feasible, key=feasible.get)
            rows_k.append([w, int(k_best), f'{feasible[k_best]:.1f}', len(feasible)])
        else:
            rows_k.append([w, '-', 'no feasible k', 0])
    table2 = _table(['w', 'entry', 'exit', 'J'], rows2)
    table3 = _table(['w', 'former (length) Dijkstra', 'improved (J) Dijkstra', ''], rows3)
    table_k = _table(['w', f'best k in {K_SWEEP[0]}..{K_SWEEP[-1]}', 'J', 'feasible k values'],
                     rows_k)

    tick('figures')
    figures = []
    paper_r = plan(th, s, g, box, replace(base, w=0.5, method='paper'))
    figures.append(plot_plan(out / 'fig8_network.png', th, box, s, g, paper_r.network.nodes,
                             paper_r.network.edges, title='Network (cf. Fig. 8)'))
    figures.append(plot_plan(out / 'fig9_dijkstra.png', th, box, s, g, paper_r.network.nodes,
                             paper_r.network.edges, initial_path=paper_r.initial_path,
                             title='Shortest path on the network (cf. Fig. 9)'))
    for w, name in ((0.2, 'fig12'), (0.5, 'fig13'), (0.8, 'fig14')):
        rr = plan(th, s, g, box, replace(base, w=w, method='improved'))
        figures.append(plot_plan(
            out / f'{name}_w{w}.png', th, box, s, g, rr.network.nodes, rr.network.edges,
            initial_path=rr.initial_path, path=rr.path,
            title=f'w={w}, k={rr.k:.0f}, J={rr.cost.J:.1f} (cf. {name.replace("fig", "Fig. ")})'))

    tick('detection table')
    table_d = detection_table(scenario, config)

    tables = {
        'Table I: J per entry/exit pair (w=0.5, k=1000)': table1,
        'Table II: best entry and exit per w (k=1000)': table2,
        'Table III: former vs improved Dijkstra node sequences (k=1000)': table3,
        'Case 3: best k per w (least J among angle-feasible paths)': table_k,
        f'Detection: paper-cost plan (w={config.w:g}) vs detection-cost plan '
        f'(w={DETECTION_W:g}), method best': table_d,
    }
    text = f'# Paper Section IV on scenario {scenario.name}\n\n' + _how(base) + '\n\n'
    text += '\n\n'.join(
        f'## {name}\n\n{body}' for name, body in tables.items())
    text += '\n\n## Figures\n\n' + '\n'.join(f'![{f.stem}]({f.name})' for f in figures) + '\n'
    (out / 'tables.md').write_text(text)
    return tables
