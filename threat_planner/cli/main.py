"""Command line: ``threat-planner plan | fly | paper | replay | batch | bag`` (and ``--version``).

Errors in the user's input (a bad scenario file, a bad option value) exit with status 2 and
one line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import atexit
import json
import math
import os
import sys
import threading

from threat_planner._version import __version__
from threat_planner.cli.bag import add_bag_commands
from threat_planner.cli.batch import (add_batch_command, add_robust_options, robust_plan,
                                      robust_summary)
from threat_planner.cli.detection_figure import add_detection_plot_option, detection_line
from threat_planner.cli.exports import add_export_options, check_exports, export_plan
from threat_planner.cli.fly import (add_fly_command, add_start_heading, enter_plan,
                                    refuse_heading_with, start_heading)
from threat_planner.cli.options import (add_planner_options, config_from, output_file,
                                        overrides, ProgressBar)
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.errors import ThreatPlannerError


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line with exit status 2."""

    def error(self, message: str) -> None:  # noqa: D102
        self.exit(2, f'{self.prog}: error: {message}\n')


def _cmd_plan(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    cfg = config_from(args, scenario)
    check_exports(args, scenario)
    heading = start_heading(args)
    if heading is not None:
        refuse_heading_with(args)
    progress = ProgressBar('sweep')
    if args.robust is not None:
        result = robust_plan(scenario, cfg, args, progress)
    elif args.record:
        from threat_planner.ros.recording.record import record_plan
        result, recording = record_plan(scenario, cfg, args.record, progress=progress)
    else:
        result = plan(scenario.threats, scenario.start, scenario.goal, scenario.box, cfg,
                      progress=progress, airspace=scenario.airspace or None)
    progress.close()
    headed = None if heading is None else enter_plan(heading, scenario, cfg, result)
    if headed is not None:
        result = headed.result
    c0, c = result.initial_cost, result.cost
    stages = ', '.join(f'{k[:-3]} {v:.1f}' for k, v in result.timings_ms.items()
                       if k != 'total_ms')
    print(f'{scenario.name}: method={cfg.method} w={cfg.w:g} threats={len(scenario.threats)}')
    print(f'  network: {result.network.n_nodes} nodes, {result.network.n_edges} edges; '
          f'entry {result.entry}, exit {result.exit}')
    print(f'  initial: J={c0.J:.3f} J_L={c0.J_L:.3f} J_R={c0.J_R:.3f}')
    k = f'k={result.k:g} ' if math.isfinite(result.k) else ''
    print(f'  final:   J={c.J:.3f} J_L={c.J_L:.3f} J_R={c.J_R:.3f} {k}'
          f'feasible={result.feasible} (pitch {result.angles.max_pitch_deg:.1f} deg, '
          f'turn {result.angles.max_turn_deg:.1f} deg)')
    if headed is not None:
        print(headed.line)
    if result.clearance is not None:
        print(f'  clearance: zones {result.clearance.zones_m:.3f} m, terrain '
              f'{result.clearance.terrain_m:.3f} m above the floor')
    print(f'  flight: {result.speed_mps:g} m/s, ETA {result.eta_s:.1f} s over '
          f'{result.eta_s * result.speed_mps:.1f} m')
    print(detection_line(result))
    print(f'  time: {result.timings_ms["total_ms"]:.1f} ms ({stages} ms)')
    robust = {}
    if args.robust is not None:
        line, robust['robust'] = robust_summary(scenario, result, args)
        print(line)
    if args.record:
        print(f'  recorded: {recording}')
    summary = result.summary() if args.json else None
    if summary is not None:
        summary.update(robust, **({} if headed is None else headed.fields))
    for line in export_plan(args, scenario, result, cfg, summary):
        print(line)
    if args.json:
        output_file(args.json).write_text(json.dumps(summary, indent=1))
    if args.plot:
        from threat_planner.cli.figures import plot_plan
        plot_plan(args.plot, scenario.threats, scenario.box, scenario.start, scenario.goal,
                  result.network.nodes, result.network.edges, result.initial_path,
                  result.path, title=f'{scenario.name}: {cfg.method}, w={cfg.w:g}, '
                                     f'J={c.J:.1f}',
                  airspace=scenario.airspace or None)
    if args.detection_plot:
        from threat_planner.cli.detection_figure import plot_detection
        plot_detection(args.detection_plot, result,
                       title=f'{scenario.name}: {cfg.method}, cost {result.cost_model}')
    return 0


def _cmd_paper(args: argparse.Namespace) -> int:
    from threat_planner.cli.reproduction import reproduce, W_SWEEP
    scenario = load_scenario(args.scenario)
    cfg = config_from(args, scenario)
    bar = ProgressBar('paper', 4 + len(W_SWEEP))   # + the detection table
    tables = reproduce(scenario, args.out, cfg, progress=bar.tick)
    bar.close()
    for name, body in tables.items():
        print(f'## {name}\n\n{body}\n')
    print(f'tables and figures written to {args.out}')
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from threat_planner.ros.recording.live import play_live
    from threat_planner.ros.recording.replay import load_bag, replay_bag
    from threat_planner.ros.recording.flight_record import is_flight_bag
    changes = overrides(args)
    if is_flight_bag(args.bag, tolerant=args.tolerant):
        from threat_planner.cli.bag import replay_flight_bag
        return replay_flight_bag(args, changes)
    bag = load_bag(args.bag, tolerant=args.tolerant)
    if args.live:
        bar = ProgressBar('live')
        live = play_live(bag, rate=args.rate, namespace=args.namespace,
                         set_parameters=not args.no_parameters, overrides=changes,
                         connect_timeout=args.timeout, wait=args.timeout, progress=bar)
        bar.close()
        params = 'set the recorded parameters, ' if live.parameters_set else ''
        print(f'{bag.path.name}: {params}published {live.published} messages and '
              f'{live.parameter_changes} parameter changes to {live.node_name} in '
              f'{live.duration_s:.1f} s (rate {args.rate:g}); {len(live.answers)} plan_info '
              'answers')
        for a in live.answers:
            print(f"  input #{a.get('input_seq')} {a.get('input_source')}: {a.get('level')}"
                  + (f" J={float(a['J']):.6g}" if 'J' in a else '')
                  + (f" ({a['error']})" if 'error' in a else ''))
        if live.last_answered is False:
            print(f'no answer to the last input within {args.timeout:g} s')
            return 1
        return 0
    bar = ProgressBar('replay')
    report = replay_bag(bag, tolerance=args.tolerance, overrides=changes, progress=bar)
    bar.close()
    print(report.table())
    print(report.summary())
    if args.report:
        output_file(args.report).write_text(report.markdown())
    return 0 if report.ok else 1


def _cmd_compile(args: argparse.Namespace) -> int:
    from threat_planner.core.compiled import compile_all, ensure_compiled
    report = ensure_compiled() if args.check else compile_all(aot=args.aot)
    print(report.line())
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of ``threat-planner``."""
    parser = _Parser(prog='threat-planner',
                     description='Threat-aware 3-D UAV path planning (Qu, Zhang, Zhang).')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}',
                        help="print the package's version (package.xml's) and exit")
    sub = parser.add_subparsers(dest='command', required=True, parser_class=_Parser)

    def planner_options(p: argparse.ArgumentParser) -> None:
        p.add_argument('scenario', help='scenario YAML file')
        add_planner_options(p)

    p_plan = sub.add_parser('plan', help='plan one scenario and print a summary')
    planner_options(p_plan)
    p_plan.add_argument('--json', help='write the result as JSON here')
    p_plan.add_argument('--plot', help='write a 3-D figure (PNG) here')
    add_detection_plot_option(p_plan)
    p_plan.add_argument('--record', metavar='OUT.mcap',
                        help='record the run to MCAP as the planner node would (parameters, '
                             'start, goal_pose, threats as float32 PointCloud2, and the '
                             'outputs); the plan is made from the float32 threats')
    add_export_options(p_plan)
    add_robust_options(p_plan)
    add_start_heading(p_plan)
    p_plan.set_defaults(func=_cmd_plan)
    add_fly_command(sub, planner_options)

    p_paper = sub.add_parser('paper', help="reproduce the paper's Section IV on a scenario")
    planner_options(p_paper)
    p_paper.add_argument('--out', required=True, help='output folder')
    p_paper.set_defaults(func=_cmd_paper)

    p_replay = sub.add_parser(
        'replay', help='re-plan a recorded run and compare with the recorded plans',
        description='Re-plan every input state of a recording (planner node or plan '
                    '--record) with its recorded parameters and compare with the recorded '
                    'outputs; fly a flight recording (fly --record) again and compare each '
                    'replan, J_flown and reached_goal. Exit status: 0 all within '
                    'tolerance, 1 a plan differs, 2 bad recording or option.')
    p_replay.add_argument('bag', help='MCAP file or rosbag2 bag directory')
    p_replay.add_argument('--tolerance', type=float, default=1e-6,
                          help='largest path point distance [m] and relative J difference '
                               'accepted (default 1e-6)')
    p_replay.add_argument('--report', metavar='OUT.md', help='also write a Markdown report')
    p_replay.add_argument('--tolerant', action='store_true',
                          help='read a recording cut off by a crash up to its last complete '
                               'chunk')
    add_planner_options(p_replay, recorded=True)
    live = p_replay.add_argument_group('live', 'publish the inputs to a running planner node')
    live.add_argument('--live', action='store_true',
                      help="publish the recorded inputs (and set the recorded parameters) "
                           "with their recorded timing to a running node instead")
    live.add_argument('--rate', type=float, default=1.0,
                      help='playback speed factor (default 1: recorded timing)')
    live.add_argument('--namespace', help='namespace of the live node (default: recorded)')
    live.add_argument('--no-parameters', action='store_true',
                      help="publish topics only; leave the node's parameters alone")
    live.add_argument('--timeout', type=float, default=30.0,
                      help='longest wait for the node and for its last answer [s]')
    p_replay.set_defaults(func=_cmd_replay)

    p_compile = sub.add_parser(
        'compile', help='compile the kernels into the cache now (make venv and colcon build '
                        'do it; tens of seconds once per install, then every process loads them)')
    p_compile.add_argument('--check', action='store_true',
                           help='only load the kernels the cache holds, compiling what it lacks')
    p_compile.add_argument('--no-aot', dest='aot', action='store_false',
                           help='fill the JIT cache only, without building the ahead-of-time '
                                'module (~60 s once per install; also THREAT_PLANNER_AOT_BUILD=0)')
    p_compile.set_defaults(func=_cmd_compile)
    add_batch_command(sub)
    add_bag_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``threat-planner``; returns the exit status."""
    parser = build_parser()
    if not (sys.argv[1:] if argv is None else argv):
        # A newcomer's first try: the usage and every subcommand, on stderr, status 2.
        parser.print_help(sys.stderr)
        return 2
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ThreatPlannerError as exc:
        print(f'threat-planner: error: {exc}', file=sys.stderr)
        return 2
    except BrokenPipeError:
        raise   # the reader left: console's to handle, not a user error
    except OSError as exc:
        # An output (or input) file the system refused: the user's path, one line.
        print(f'threat-planner: error: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('threat-planner: interrupted', file=sys.stderr)
        return 130


def console() -> None:
    """Run ``threat-planner`` as a script: :func:`main`, the exit functions, and leave.

    Interpreter teardown (freeing numba's loaded kernels and every module) took 0.15-0.3 s
    after a plan's last output. With the work done, the registered exit functions run
    (logging, finalizers) and the process leaves without it. In-process callers of
    :func:`main` are unaffected; a script with threads still running exits normally.
    Output into a closed pipe ends the script with status 1, without a traceback.
    """
    try:
        status = main()
    except BrokenPipeError:
        # The reader left (| head): no traceback; stdout goes nowhere from here, as the
        # Python documentation's SIGPIPE note does it.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        status = 1
    run_exit_functions = getattr(atexit, '_run_exitfuncs', None)
    if run_exit_functions is None or threading.active_count() > 1:
        sys.exit(status)
    run_exit_functions()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass  # a closed pipe (| head): the output was not wanted
    os._exit(status)


if __name__ == '__main__':
    console()
