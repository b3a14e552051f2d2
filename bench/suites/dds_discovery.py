"""The executables' Fast DDS discovery profile against Fast DDS's defaults: first paths.

``planner_node`` (``python -m threat_planner.ros.entry planner_node``) and a
``threat_publisher`` of the 20-threat scenario are started as in ``node_start``, the
publisher beside the node and 3 s before it, with the package's discovery profile (the
default of its executables, :mod:`threat_planner.ros.discovery`) and with
``THREAT_PLANNER_DDS_PROFILE=0`` (Fast DDS's own timing: initial announcements 5 x 0.1 s,
then one every 3 s), taking turns. Seconds from the start of the node process to its
first path, from the node's log stamps. Then a bare rclpy probe: a publisher running
for 3 s, and fresh probe processes, one after another, each subscribing to its latched
threats as soon as rclpy is up: seconds from subscribing to the first message, with the
profile on neither side, on the probe's, on the publisher's, on both. Writes
``bench/results/dds_discovery.md``.

Usage: ``python -m bench dds_discovery [--repeats N] [--probes N]``
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import statistics
import subprocess
import sys
import time

from bench.suites.node_start import discovery_env, start_once
from bench.toolkit.checkouts import short_commit
from bench.toolkit.repo import DATA, machine, RESULTS, ROOT

MODES = (('profile', True), ('Fast DDS defaults', False))
PLACES = (('beside the node', False), ('3 s before the node', True))
#: (probe side, publisher side) of the profile.
PROBE_SIDES = (('neither', False, False), ('the probe', True, False),
               ('the publisher', False, True), ('both', True, True))
PROBE = """
import time
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from threat_planner.ros.interface import THREAT_INPUT
rclpy.init()
node = Node('discovery_probe')
got = []
t0 = time.monotonic()
node.create_subscription(PointCloud2, 'threats', lambda m: got.append(time.monotonic()),
                         THREAT_INPUT)
while not got and time.monotonic() - t0 < 10.0:
    rclpy.spin_once(node, timeout_sec=0.01)
print(got[0] - t0 if got else float('nan'))
node.destroy_node()
rclpy.shutdown()
"""


def probe_waits(domain: int, on_probe: bool, on_publisher: bool, probes: int) -> list:
    """Seconds from subscribing to the first message, for `probes` fresh probe processes."""
    from bench.toolkit.node import stop_process
    publisher = subprocess.Popen(
        [sys.executable, '-m', 'threat_planner.ros.publisher', '--ros-args', '-p',
         f'scenario:={DATA / "uniform20_0.yaml"}'], env=discovery_env(domain, on_publisher),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    waits = []
    try:
        time.sleep(3.0)
        for _ in range(probes):
            done = subprocess.run([sys.executable, '-c', PROBE],
                                  env=discovery_env(domain, on_probe), capture_output=True,
                                  text=True, timeout=60)
            waits.append(float(done.stdout.split()[-1]) if done.stdout.split()
                         else float('nan'))
    finally:
        stop_process(publisher)
    return waits


def main(argv: list[str] | None = None) -> int:
    """Start the node with and without the profile in turns; write the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--repeats', type=int, default=10, help='starts per mode and placement')
    ap.add_argument('--probes', type=int, default=14, help='probe processes per side')
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
    lines += ['', f'Bare probe, {args.probes} fresh processes per row, the publisher running '
              'for 3 s before the first: seconds from subscribing to the latched picture.',
              '', '| profile on | median | max | over 1 s | each probe |',
              '|---|---:|---:|---:|---|']
    for k, (side, on_probe, on_publisher) in enumerate(PROBE_SIDES):
        xs = probe_waits(190 + k, on_probe, on_publisher, args.probes)
        print(side, [round(x, 2) for x in xs], flush=True)
        lines.append(f'| {side} | {statistics.median(xs):.2f} | {max(xs):.2f} | '
                     f'{sum(x > 1.0 for x in xs)} of {len(xs)} | '
                     + ', '.join(f'{x:.2f}' for x in xs) + ' |')
    text = '\n'.join(lines) + '\n'
    args.out.write_text(text)
    print(text)
    return 0
