"""Command line: ``threat-planner bag repair IN [OUT]``, and ``replay`` of a flight bag."""

from __future__ import annotations

import argparse

from threat_planner.errors import InputError


def replay_flight_bag(args: argparse.Namespace, changes: dict) -> int:
    """Replay a flight bag (``fly --record``): one line per plan and a verdict; 0 or 1."""
    from threat_planner.ros.recording.flight_replay import replay_flight
    if args.live:
        raise InputError(f'--live: {args.bag} is a flight recording (fly --record); '
                         'replay it without --live')
    report = replay_flight(args.bag, tolerance=args.tolerance, overrides=changes,
                           tolerant=args.tolerant)
    for line in report.lines():
        print(line)
    if args.report:
        from threat_planner.cli.options import output_file
        output_file(args.report).write_text(report.markdown())
    return 0 if report.ok else 1


def _cmd_repair(args: argparse.Namespace) -> int:
    from threat_planner.bag.repair import repair_recording
    if args.in_place and args.out is not None:
        args.parser.error('OUT cannot be given with --in-place')
    report = repair_recording(args.bag, args.out, in_place=args.in_place,
                              fix_cdr=args.fix_cdr)
    print(report.summary())
    return 0


def add_bag_commands(sub) -> None:
    """Register ``bag`` and its verbs on the subparsers of ``threat-planner``."""
    p_bag = sub.add_parser('bag', help='tools for recordings (MCAP files, rosbag2 bags)')
    verbs = p_bag.add_subparsers(dest='verb', required=True, parser_class=type(p_bag))
    p_repair = verbs.add_parser(
        'repair', help='rewrite a recording cut off by a crash as a complete file',
        description='Copy every complete chunk of a damaged MCAP file (or of each file of '
                    'a rosbag2 bag directory, whose metadata.yaml is rewritten) with its '
                    'schemas, channels and metadata into a new file with index, summary '
                    'and footer. Exit status 2 when IN is not MCAP.')
    p_repair.add_argument('bag', metavar='IN', help='MCAP file or rosbag2 bag directory')
    p_repair.add_argument('out', metavar='OUT', nargs='?',
                          help='output (default: IN with .repaired.mcap, or IN.repaired '
                               'for a directory)')
    p_repair.add_argument('--in-place', action='store_true',
                          help='replace IN (written to a temporary file, then renamed)')
    p_repair.add_argument('--fix-cdr', action='store_true',
                          help='also cut CDR payloads to their exact length and zero their '
                               'padding (bags written before this fix open in rosbags)')
    p_repair.set_defaults(func=_cmd_repair, parser=p_repair)
