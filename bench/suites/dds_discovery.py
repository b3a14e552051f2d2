"""The executables' Fast DDS discovery profile against Fast DDS's defaults: first paths.

``planner_node`` (``python -m threat_planner.ros.entry planner_node``) and a
``threat_publisher`` of the 20-threat scenario are started as in ``node_start``, the
publisher beside the node and 3 s before it, with the package's discovery profile (the
default of its executables, :mod:`threat_planner.ros.discovery`) and with
``THREAT_PLANNER_DDS_PROFILE=0`` (Fast DDS's own timing: initial announcements 5 x 0.1 s,
then one every 3 s), taking turns. Seconds from the start of the node process to its
first path, from the node's log stamps. Writes ``bench/results/dds_discovery.md``.

Usage: ``python -m bench dds_discovery [--repeats N]``
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import statistics
import time

from bench.suites.node_start import start_once
from bench.toolkit.checkouts import short_commit
from bench.toolkit.repo import machine, RESULTS, ROOT

MODES = (('profile', True), ('Fast DDS defaults', False))
PLACES = (('beside the node', False), ('3 s before the node', True))


def main(argv: list[str] | None = None) -> int:
    """Start the node with and without the profile in turns; write the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--repeats', type=int, default=10, help='starts per mode and placement')
    ap.add_argument('--out', type=Path, default=RESULTS / 'dds_discovery.md')
    args = ap.parse_args(argv)
    work = Path(os.environ.get('TMPDIR', '/tmp')) / f'dds_discovery_{os.getpid()}'
    work.mkdir(parents=True, exist_ok=True)
    firsts: dict[tuple[str, str], list[float]] = {}
    start = 0
    for place, publisher_first in PLACES:
        for turn in range(args.repeats):
            order = MODES if turn % 2 == 0 else MODES[::-1]
            for mode, profile in order:
                start += 1
                r = start_once(ROOT, work, 150 + start % 40, publisher_first, profile)
                firsts.setdefault((place, mode), []).append(r['first_path_s'])
                print(place, mode, round(r['first_path_s'], 2), flush=True)
    lines = ['# DDS discovery profile against Fast DDS defaults', '',
             f'`python -m bench dds_discovery` on {time.strftime("%Y-%m-%d %H:%M")} at '
             f'`{short_commit(ROOT)}`: `planner_node` and `threat_publisher` (20 threats), '
             f'{args.repeats} starts per row, the modes in turns; {machine()}, load average '
             'at the end ' + ', '.join(f'{x:.1f}' for x in os.getloadavg()) + '. Seconds '
             'from the start of the node process to its first path; ROS discovery range '
             'LOCALHOST.', '',
             '| publisher started | discovery | median | max | over 1 s | each start |',
             '|---|---|---:|---:|---:|---|']
    for place, _ in PLACES:
        for mode, _ in MODES:
            xs = firsts[(place, mode)]
            lines.append(f'| {place} | {mode} | {statistics.median(xs):.2f} | {max(xs):.2f} '
                         f'| {sum(x > 1.0 for x in xs)} of {len(xs)} | '
                         + ', '.join(f'{x:.2f}' for x in xs) + ' |')
    text = '\n'.join(lines) + '\n'
    args.out.write_text(text)
    print(text)
    return 0
