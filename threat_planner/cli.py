"""Command line: ``threat-planner plan | paper``.

Errors in the user's input (a bad scenario file, a bad option value) exit with status 2 and
one line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
from pathlib import Path
import sys

from threat_planner.errors import ThreatPlannerError
from threat_planner.planner import METHODS, plan, PlannerConfig
from threat_planner.scenario import load_scenario


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line with exit status 2."""

    def error(self, message: str) -> None:  # noqa: D102
        self.exit(2, f'{self.prog}: error: {message}\n')


def _config_from(args: argparse.Namespace) -> PlannerConfig:
    cfg = PlannerConfig(w=args.w, method=args.method)
    if args.k is not None:
        cfg = replace(cfg, k=args.k)
    if args.auto_k:
        cfg = replace(cfg, auto_k=True)
    if args.n_points is not None:
        cfg = replace(cfg, n_points=args.n_points)
    if args.max_pitch is not None:
        cfg = replace(cfg, max_pitch_deg=args.max_pitch)
    if args.max_turn is not None:
        cfg = replace(cfg, max_turn_deg=args.max_turn)
    if args.entry_candidates is not None:
        cfg = replace(cfg, entry_candidates=args.entry_candidates)
    if args.leave_box:
        cfg = replace(cfg, confine_to_box=False)
    return cfg.validated()


def _progress_bar(total: int, desc: str):
    """Make a tqdm bar on stderr, shown only for sweeps that run for more than a second."""
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, delay=1.0, leave=False, file=sys.stderr)


def _cmd_plan(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    cfg = _config_from(args)
    bar = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if bar is None:
            bar = _progress_bar(total, 'sweep')
        bar.update(done - bar.n)

    result = plan(scenario.threats, scenario.start, scenario.goal, scenario.box, cfg,
                  progress=progress)
    if bar is not None:
        bar.close()
    c0, c = result.initial_cost, result.cost
    stages = ', '.join(f'{k[:-3]} {v:.1f}' for k, v in result.timings_ms.items()
                       if k != 'total_ms')
    print(f'{scenario.name}: method={cfg.method} w={cfg.w:g} threats={len(scenario.threats)}')
    print(f'  network: {result.network.n_nodes} nodes, {result.network.n_edges} edges; '
          f'entry {result.entry}, exit {result.exit}')
    print(f'  initial: J={c0.J:.3f} J_L={c0.J_L:.3f} J_R={c0.J_R:.3f}')
    print(f'  final:   J={c.J:.3f} J_L={c.J_L:.3f} J_R={c.J_R:.3f} k={result.k:g} '
          f'feasible={result.feasible} (pitch {result.angles.max_pitch_deg:.1f} deg, '
          f'turn {result.angles.max_turn_deg:.1f} deg)')
    print(f'  time: {result.timings_ms["total_ms"]:.1f} ms ({stages} ms)')
    if args.json:
        Path(args.json).write_text(json.dumps(result.summary(), indent=1))
    if args.plot:
        from threat_planner.figures import plot_plan
        plot_plan(args.plot, scenario.threats, scenario.box, scenario.start, scenario.goal,
                  result.network.nodes, result.network.edges, result.initial_path,
                  result.path, title=f'{scenario.name}: {cfg.method}, w={cfg.w:g}, '
                                     f'J={c.J:.1f}')
    return 0


def _cmd_paper(args: argparse.Namespace) -> int:
    from threat_planner.reproduction import reproduce, W_SWEEP
    scenario = load_scenario(args.scenario)
    cfg = _config_from(args)
    bar = _progress_bar(3 + len(W_SWEEP), 'paper')

    def tick(label: str) -> None:
        bar.set_postfix_str(label)
        bar.update(1)

    tables = reproduce(scenario, args.out, cfg, progress=tick)
    bar.close()
    for name, body in tables.items():
        print(f'## {name}\n\n{body}\n')
    print(f'tables and figures written to {args.out}')
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of ``threat-planner``."""
    parser = _Parser(prog='threat-planner',
                     description='Threat-aware 3-D UAV path planning (Qu, Zhang, Zhang).')
    sub = parser.add_subparsers(dest='command', required=True, parser_class=_Parser)

    def planner_options(p: argparse.ArgumentParser) -> None:
        p.add_argument('scenario', help='scenario YAML file')
        p.add_argument('--w', type=float, default=0.5, help='threat weight, 0 < w < 1')
        p.add_argument('--method', choices=METHODS, default='best')
        p.add_argument('--k', type=float, help='spring coefficient (default 1000)')
        p.add_argument('--auto-k', action='store_true',
                       help='sweep k over 500..3000 for least J (Case 3)')
        p.add_argument('--n-points', type=int, help='path segments (default 40)')
        p.add_argument('--max-pitch', type=float, help='pitch limit [deg] (default 45)')
        p.add_argument('--max-turn', type=float, help='turn limit [deg] (default 60)')
        p.add_argument('--entry-candidates', type=int, help='K entry/exit candidates')
        p.add_argument('--leave-box', action='store_true',
                       help='let the optimised path leave the bounds box')

    p_plan = sub.add_parser('plan', help='plan one scenario and print a summary')
    planner_options(p_plan)
    p_plan.add_argument('--json', help='write the result as JSON here')
    p_plan.add_argument('--plot', help='write a 3-D figure (PNG) here')
    p_plan.set_defaults(func=_cmd_plan)

    p_paper = sub.add_parser('paper', help="reproduce the paper's Section IV on a scenario")
    planner_options(p_paper)
    p_paper.add_argument('--out', required=True, help='output folder')
    p_paper.set_defaults(func=_cmd_paper)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``threat-planner``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ThreatPlannerError as exc:
        print(f'threat-planner: error: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('threat-planner: interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
