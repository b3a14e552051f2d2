"""Re-record the regression bags of ``test/data/bags/`` with the live planner node.

``test/ros/test_replay.py`` replays every bag in ``test/data/bags/`` (``threat-planner replay``):
it re-plans each input state the bag holds with the parameters the bag holds and fails
on any difference from the recorded plans. The bags therefore pin the planner's current
output. When the planner's results change **on purpose** (the algorithm is tuned, a
default changes), the test fails and names the first plan that differs; re-record the
bags with one command::

    .venv/bin/python -m bench record_regression_bags

and commit the changed ``test/data/bags/*.mcap`` together with the change that moved the
plans (look at the replay table first: the differences it shows should be the ones you
meant). Other uses::

    .venv/bin/python -m bench record_regression_bags --only moving_uniform20
    .venv/bin/python -m bench record_regression_bags --check   # replay only, record nothing

(``bench/record_regression_bags.py``, the command the replay test quotes, runs this suite.)
For each bag the suite does what a user does: it starts ``planner_node`` with parameter
``record`` set to a temporary folder (a rosbag2 bag per run) and the scenario's bounds,
start, goal and frame as parameters, and ``threat_publisher`` with the scenario, both as
their own processes in a ROS domain of their own with discovery limited to this host
(as the tests do). When the node has answered its last input and has been quiet for a
moment, both get SIGTERM (so the recording is finished properly), the bag is replayed
once to make sure it reproduces, and its ``.mcap`` is copied to ``test/data/bags/``.

The bags:

* ``uniform20``: the bundled 20-threat scenario ``test/data/uniform20_0.yaml`` with the
  default settings (method ``best``), the picture published once (latched).
* ``ground``: the ground-radar scenario ``test/data/ground_0.yaml``, method ``best``.
* ``moving_uniform20``: ``uniform20_0.yaml`` with the threats drifting (``rate`` 2 Hz,
  ``drift`` 3 m/s random walk, seed 1) for several replans, method ``paper`` so that the
  replay stays fast.

Each bag is well under 1 MB (the ``network`` MarkerArrays are most of it).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
import shutil
import signal
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray

from bench.toolkit.node import (info, planner_command, PYTHON, RosClient, ros_session,
                                scenario_params, start_process, stop_process)
from bench.toolkit.repo import DATA, ROOT
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.ros.recording.replay import load_bag, replay_bag

BAGS_DIR = DATA / 'bags'
MAX_BYTES = 1_000_000
#: Re-recording command, as ``test/ros/test_replay.py`` quotes it (the shim runs this).
COMMAND = '.venv/bin/python bench/record_regression_bags.py'


@dataclass(frozen=True)
class BagSpec:
    """One regression bag: the scenario, planner parameters and publisher parameters."""

    name: str
    scenario: Path
    params: dict = field(default_factory=dict)
    publisher: dict = field(default_factory=dict)
    #: Threat pictures to wait for (plans answering the threats topic).
    pictures: int = 1


BAGS = (
    BagSpec('uniform20', DATA / 'uniform20_0.yaml'),
    BagSpec('ground', DATA / 'ground_0.yaml'),
    BagSpec('moving_uniform20', DATA / 'uniform20_0.yaml', {'method': 'paper'},
            {'rate': 2.0, 'drift': 3.0, 'drift_mode': 'random_walk', 'seed': 1}, pictures=6),
)


def _quiet(client: RosClient, topic: str, settle: float, timeout: float) -> None:
    """Wait until the node has answered its latest input and sent nothing for `settle` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        count = client.count(topic)
        last = client.last(topic)
        if last is not None:
            values = info(last)
            if int(values['input_seq']) == int(values['inputs_received']):
                time.sleep(settle)
                if client.count(topic) == count:
                    return
                continue
        time.sleep(0.1)
    raise TimeoutError(f'the planner did not settle within {timeout} s')


def record(spec: BagSpec, client: RosClient, work: Path, timeout: float) -> Path:
    """Record one bag with the live node and publisher; return the finished .mcap."""
    scenario = load_scenario(spec.scenario)
    folder = work / spec.name
    params = scenario_params(scenario, record=str(folder), **spec.params)
    client.subscribe('/plan_info', DiagnosticArray)
    node = start_process(planner_command('', params), client.domain, work / f'{spec.name}.log')
    publisher = None
    try:
        # The node has opened its recording once it subscribes to its inputs.
        client.wait_until(lambda: client.node.count_subscribers('/threats') > 0, 30.0,
                          'the planner node')
        cmd = [PYTHON, '-m', 'threat_planner.ros.publisher', '--ros-args',
               '-p', f'scenario:={spec.scenario}']
        for name, value in spec.publisher.items():
            cmd += ['-p', f'{name}:={value}']
        publisher = start_process(cmd, client.domain, work / f'{spec.name}_publisher.log')
        deadline = time.monotonic() + timeout
        while True:
            plans = [info(m) for _, m in list(client.messages.get('/plan_info', []))]
            pictures = {int(v['input_stamp_ns']) for v in plans
                        if v['input_source'] == '/threats' and v['level'] != 'ERROR'}
            # A plan slower than the worker's stale limit (1 s) gives way to the start and
            # goal the publisher re-sends on matching: the plan that answers them holds the
            # one threat picture as well.
            held = any(v['level'] != 'ERROR' and int(v.get('threats', 0)) > 0 for v in plans)
            if len(pictures) >= spec.pictures or (spec.pictures == 1 and held):
                break
            if time.monotonic() > deadline or node.poll() is not None:
                raise TimeoutError(f'{spec.name}: {len(pictures)} of {spec.pictures} threat '
                                   f'pictures planned within {timeout} s; see {work}')
            time.sleep(0.1)
        stop_process(publisher)
        publisher = None
        _quiet(client, '/plan_info', settle=1.5, timeout=timeout)
    finally:
        if publisher is not None:
            stop_process(publisher)
        code = stop_process(node, signal.SIGTERM, timeout=60.0)
        client.unsubscribe('/plan_info')
    if code != 0:
        raise RuntimeError(f'{spec.name}: planner exited with {code}; see {work}')
    (bag_dir,) = [d for d in folder.iterdir() if d.is_dir()]
    (mcap,) = bag_dir.glob('*.mcap')
    return mcap


def check(path: Path) -> str:
    """Replay one bag; return a one-line verdict (raises nothing for a difference)."""
    report = replay_bag(load_bag(path))
    size = path.stat().st_size
    return f'{path.name}: {size / 1024:.0f} KiB, {report.summary()}'


def main(argv: list[str] | None = None) -> int:
    """Record (or with --check only replay) the regression bags."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', action='append', choices=[b.name for b in BAGS],
                        help='record only this bag (repeatable)')
    parser.add_argument('--out', type=Path, default=BAGS_DIR, help='destination folder')
    parser.add_argument('--check', action='store_true',
                        help='replay the bags in --out and report; record nothing')
    parser.add_argument('--timeout', type=float, default=300.0, help='per bag [s]')
    args = parser.parse_args(argv)
    specs = [b for b in BAGS if not args.only or b.name in args.only]
    if args.check:
        verdicts = [check(args.out / f'{b.name}.mcap') for b in specs]
        print('\n'.join(verdicts))
        return 0 if all('REGRESSION' not in v for v in verdicts) else 1

    args.out.mkdir(parents=True, exist_ok=True)
    with ros_session(89, 2, 'record_regression_bags', 'regression_bags_') as (client, tmp):
        for spec in specs:
            mcap = record(spec, client, tmp, args.timeout)
            report = replay_bag(load_bag(mcap))
            if not report.ok:
                raise RuntimeError(f'{spec.name}: the fresh recording does not replay: '
                                   f'{report.summary()}')
            target = args.out / f'{spec.name}.mcap'
            shutil.copyfile(mcap, target)
            size = target.stat().st_size
            print(f'{target.relative_to(ROOT) if target.is_relative_to(ROOT) else target}:'
                  f' {size / 1024:.0f} KiB, {len(report.rows)} plans, '
                  f'{len(report.bag.inputs)} inputs', flush=True)
            if size > MAX_BYTES:
                print(f'warning: {target.name} is larger than {MAX_BYTES} bytes',
                      file=sys.stderr)
    return 0
