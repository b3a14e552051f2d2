"""The flight regression bags of ``test/data/bags/``: what they fly, and how to record them.

``test/ros/test_flight_bag.py`` replays each (``threat-planner replay``), so they pin what
``threat-planner fly`` does. When the flight changes on purpose, record them again with::

    .venv/bin/python test/ros/flight_bags.py            # both; --only NAME for one
    .venv/bin/python test/ros/flight_bags.py --check    # replay only, record nothing

and commit the changed ``test/data/bags/flight_*.mcap`` with the change that moved them.
Each is ``threat-planner fly SCENARIO --events EVENTS --record BAG --record-no-latency``:
without the wall-clock latencies, the same flight records to the same bytes, so a bag
only changes when the flight does.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import subprocess
import sys

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / 'test' / 'data'
BAGS = DATA / 'bags'
#: Largest size of a flight bag [bytes].
MAX_BYTES = 300_000
#: name -> (scenario, events file), both relative to the repository.
FLIGHTS = {
    # pop-up with a lethal radius, a threat set moving, a removal and a new goal
    'flight_popup': ('test/data/uniform20_0.yaml', 'examples/flight/popup.yaml'),
    # a pop-up that moves across the route, a scenario threat set moving, a new goal
    'flight_moving': ('test/data/uniform20_0.yaml', 'test/data/flights/moving.yaml'),
}


def fly_command(name: str, target: Path, *, latency: bool = False) -> list[str]:
    """Return the command line that records flight `name` into `target`."""
    scenario, events = FLIGHTS[name]
    return [sys.executable, '-m', 'threat_planner.cli', 'fly', str(REPO / scenario),
            '--events', str(REPO / events), '--record', str(target),
            *([] if latency else ['--record-no-latency'])]


def record(name: str, target: Path, *, latency: bool = False) -> subprocess.CompletedProcess:
    """Record flight `name` into `target` (a ``.mcap`` file)."""
    return subprocess.run(fly_command(name, target, latency=latency), capture_output=True,
                          text=True, timeout=300, cwd=REPO)


def replay(bag: Path, *options: str) -> subprocess.CompletedProcess:
    """Replay `bag` with ``threat-planner replay``."""
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'replay', str(bag),
                           *options], capture_output=True, text=True, timeout=300, cwd=REPO)


def main(argv: list[str] | None = None) -> int:
    """Record (or with --check only replay) the flight bags; print one line each."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', action='append', choices=sorted(FLIGHTS))
    parser.add_argument('--check', action='store_true', help='replay only, record nothing')
    args = parser.parse_args(argv)
    status = 0
    for name in args.only or list(FLIGHTS):
        bag = BAGS / f'{name}.mcap'
        if not args.check:
            p = record(name, bag)
            if p.returncode != 0:
                print(f'{name}: fly failed: {p.stderr.strip()}', file=sys.stderr)
                return 1
        p = replay(bag)
        verdict = p.stdout.strip().splitlines()[-1] if p.stdout.strip() else p.stderr.strip()
        print(f'{bag.relative_to(REPO)}: {bag.stat().st_size / 1024:.0f} KiB; {verdict}')
        if bag.stat().st_size > MAX_BYTES:
            print(f'warning: {bag.name} is larger than {MAX_BYTES} bytes', file=sys.stderr)
        status = max(status, p.returncode)
    return status


if __name__ == '__main__':
    sys.exit(main())
