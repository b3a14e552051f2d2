"""Node start, two checkouts side by side: seconds from starting planner_node to its first path.

``python -m bench node_start BASE``: the node of BASE (``python -m threat_planner.ros.node``
on its sources) and of this checkout (``python -m threat_planner.ros.entry planner_node``,
what the installed ``planner_node`` runs), started in turns, each with a
``threat_publisher`` of the 20-threat scenario started beside it (or, with
``--publisher-first``, 3 s before it). The clocks are the node's own log stamps of its
'kernels', 'ready' and first 'plan for input' lines, from the moment the process was
started. Both use this machine's compiled cache (``threat-planner compile`` run for each);
a checkout before ``threat_planner.ros.entry`` has no prestarted plan process.

Writes ``bench/results/node_start.md``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import statistics
import subprocess
import sys
import time

from bench.toolkit.checkouts import short_commit
from bench.toolkit.repo import DATA, machine, RESULTS, ROOT

KEYS = (('kernels_s', ']: kernels: '), ('ready_s', ']: ready: '),
        ('first_path_s', ']: plan for input #'))


def discovery_env(domain: int, profile: bool) -> dict:
    """Return a ROS process environment with or without the package's discovery profile.

    Without it (`profile` False) the process runs on Fast DDS's default timing
    (:mod:`threat_planner.ros.discovery` switched off).
    """
    import bench.toolkit.node  # noqa: F401 - puts test/ on the path
    from node_harness import ros_env
    from threat_planner.ros.discovery import PROFILE_VARIABLES, SWITCH
    env = ros_env(domain)
    if not profile:
        for name in PROFILE_VARIABLES:
            env.pop(name, None)
        env[SWITCH] = '0'
    return env


def start_once(tree: Path, work: Path, domain: int, publisher_first: bool,
               discovery_profile: bool = True) -> dict:
    """Start the node of `tree` and a publisher; return the seconds of :data:`KEYS`.

    Both run on the package's discovery profile, or on Fast DDS's defaults
    (:func:`discovery_env`).
    """
    from bench.toolkit.node import log_stamp, stop_process
    env = discovery_env(domain, discovery_profile)
    env['PYTHONPATH'] = os.pathsep.join([str(tree), env['PYTHONPATH']])
    has_entry = (tree / 'threat_planner' / 'ros' / 'entry.py').exists()
    node = [sys.executable, '-m'] + (['threat_planner.ros.entry', 'planner_node'] if has_entry
                                     else ['threat_planner.ros.node'])
    node += ['--ros-args', '--params-file', str(ROOT / 'config' / 'planner.yaml')]
    publisher = [sys.executable, '-m', 'threat_planner.ros.publisher', '--ros-args', '-p',
                 f'scenario:={DATA / "uniform20_0.yaml"}']
    log = work / 'node.log'
    procs = []

    def run(cmd: list, path: Path) -> None:
        with open(path, 'wb') as out:
            procs.append(subprocess.Popen(cmd, env=env, cwd=work, stdout=out,
                                          stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL))
    try:
        if publisher_first:
            run(publisher, work / 'publisher.log')
            time.sleep(3.0)
        t0 = time.time()
        run(node, log)
        if not publisher_first:
            run(publisher, work / 'publisher.log')
        deadline = time.time() + 120.0
        while time.time() < deadline and KEYS[-1][1] not in log.read_text(errors='replace'):
            time.sleep(0.02)
    finally:
        for p in reversed(procs):
            stop_process(p)
    stamps = {key: log_stamp(log, text) for key, text in KEYS}
    return {key: float('nan') if t is None else t - t0 for key, t in stamps.items()}


def main(argv: list[str] | None = None) -> int:
    """Start both checkouts' nodes in turns and write the medians."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('base', type=Path, help='the other checkout (the "before")')
    ap.add_argument('--repeats', type=int, default=8, help='starts per checkout')
    ap.add_argument('--publisher-first', action='store_true',
                    help='start the publisher 3 s before the node')
    ap.add_argument('--out', type=Path, default=RESULTS / 'node_start.md')
    args = ap.parse_args(argv)
    trees = {'before': args.base.resolve(), 'after': ROOT}
    runs: dict[str, list[dict]] = {k: [] for k in trees}
    work = Path(os.environ.get('TMPDIR', '/tmp')) / f'node_start_{os.getpid()}'
    work.mkdir(parents=True, exist_ok=True)
    for turn in range(args.repeats):
        order = ('before', 'after') if turn % 2 == 0 else ('after', 'before')
        for name in order:
            r = start_once(trees[name], work, 150 + (2 * turn + (name == 'after')) % 40,
                           args.publisher_first)
            runs[name].append(r)
            print(name, {k: round(v, 2) for k, v in r.items()}, flush=True)
    med = {n: {k: statistics.median(r[k] for r in rs) for k, _ in KEYS}
           for n, rs in runs.items()}
    when = 'started 3 s before the node' if args.publisher_first else 'started with the node'
    lines = ['# Node start, side by side', '',
             f'`python -m bench node_start` on {time.strftime("%Y-%m-%d %H:%M")}: before = '
             f'`{short_commit(trees["before"])}`, after = `{short_commit(ROOT)}`, '
             f'{args.repeats} starts each in turns, the publisher {when}; {machine()}, load '
             'average at the end '
             + ', '.join(f'{x:.1f}' for x in os.getloadavg()) + '. Seconds from the start of '
             'the node process (medians).', '',
             '| checkout | kernels line | ready | first path | first paths (each start) |',
             '|---|---:|---:|---:|---|']
    for name in trees:
        m = med[name]
        each = ', '.join(f"{r['first_path_s']:.2f}" for r in runs[name])
        lines.append(f"| {name} | {m['kernels_s']:.2f} | {m['ready_s']:.2f} | "
                     f"{m['first_path_s']:.2f} | {each} |")
    ratio = med['after']['first_path_s'] / med['before']['first_path_s']
    lines += ['', f'First path after/before: {ratio:.2f}.']
    text = '\n'.join(lines) + '\n'
    args.out.write_text(text)
    print(text)
    return 0
