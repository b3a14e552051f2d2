"""End-to-end latency of the planner node: publish a threat picture, receive ``path``.

For each scenario and method a planner node is started as its own process (in a ROS domain
of its own, discovery limited to this host), given the scenario's bounds, start and goal as
parameters, and sent the scenario's threats as a PointCloud2 once to warm up and then
``--repeats`` more times, each picture moved by a few centimetres so that it is a new one.
The time from ``publish()`` to the arrival of the ``path`` answering that picture (matched
by header stamp) is the latency; ``plan_info``'s ``plan_wall_ms`` is the planner's share and
the rest ("node + transport") is decoding, path messages, transport and scheduling. The
RViz markers are drawn after ``path`` is out; their time ("markers") is shown apart.

Usage::

    .venv/bin/python -m bench node_latency                      # 20, 300, 1000 threats
    .venv/bin/python -m bench node_latency --methods paper --repeats 5
    .venv/bin/python -m bench node_latency --out bench/results/node_latency.md
"""

from __future__ import annotations

import argparse
from pathlib import Path
import statistics
import sys

from builtin_interfaces.msg import Time
import numpy as np
from sensor_msgs.msg import PointCloud2

from bench.toolkit.node import (cloud, jitter, planner_command, RosClient, ros_session,
                                round_trip, scenario_params, start_process, stop_process,
                                subscribe_answers)
from bench.toolkit.repo import DATA, SHARED
from bench.toolkit.report import md_table
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.ros.conversions import stamp_to_ns

DEFAULT_SCENARIOS = (DATA / 'uniform20_0.yaml', DATA / 'big300_0.yaml',
                     SHARED / 'scale1000.yaml')


def measure(client: RosClient, scenario_path: Path, method: str, repeats: int,
            timeout: float, log_dir: Path) -> dict:
    """Start a node for one scenario and method; return its latency statistics [ms]."""
    scenario = load_scenario(scenario_path)
    ns = f'/bench_{method}_{len(scenario.threats)}'
    proc = start_process(planner_command(ns, scenario_params(scenario, method=method)),
                         client.domain, log_dir / f'{ns.strip("/")}.log')
    latencies, plan_ms, messages_ms = [], [], []
    try:
        subscribe_answers(client, ns)
        client.wait_matched(client.publisher(f'{ns}/threats', PointCloud2), timeout=30.0)
        rng = np.random.default_rng(0)
        for run in range(repeats + 1):
            stamp = Time(sec=1000 + run)
            msg = cloud(jitter(scenario.threats.positions, rng),
                        scenario.threats.intensities, scenario.frame_id, stamp)
            latency, _, values = round_trip(client, ns, msg, timeout, scenario_path.name)
            if run == 0:
                continue  # warm-up: first-call costs (imports, caches) are not steady state
            latencies.append(latency)
            plan_ms.append(float(values['plan_wall_ms']))
            messages_ms.append(float(values['messages_ms']))
            assert stamp_to_ns(stamp) == int(values['input_stamp_ns'])
    finally:
        stop_process(proc)
    overhead = [a - b for a, b in zip(latencies, plan_ms)]
    return {'scenario': scenario.name, 'threats': len(scenario.threats), 'method': method,
            'runs': len(latencies), 'median': statistics.median(latencies),
            'min': min(latencies), 'max': max(latencies),
            'plan': statistics.median(plan_ms), 'messages': statistics.median(messages_ms),
            'overhead': statistics.median(overhead)}


def table(rows: list[dict]) -> str:
    """Return the Markdown table of the measurements."""
    return '\n'.join(md_table(
        ['scenario', 'threats', 'method', 'runs', 'latency median [ms]', 'min [ms]',
         'max [ms]', 'plan [ms]', 'node + transport [ms]', 'markers [ms]'],
        ([r['scenario'], r['threats'], r['method'], r['runs'], f"{r['median']:.0f}",
          f"{r['min']:.0f}", f"{r['max']:.0f}", f"{r['plan']:.0f}", f"{r['overhead']:.1f}",
          f"{r['messages']:.1f}"] for r in rows), 'lrlrrrrrrr'))


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('scenarios', nargs='*', type=Path, default=list(DEFAULT_SCENARIOS))
    parser.add_argument('--methods', default='paper,best',
                        help='comma-separated planner methods (default: paper,best)')
    parser.add_argument('--repeats', type=int, default=3, help='timed runs after a warm-up')
    parser.add_argument('--timeout', type=float, default=600.0, help='per plan [s]')
    parser.add_argument('--out', type=Path, help='also write the table to this file')
    args = parser.parse_args(argv)

    rows = []
    with ros_session(91, 10, 'node_latency_bench', 'node_latency_') as (client, tmp):
        for path in args.scenarios:
            for method in args.methods.split(','):
                row = measure(client, path, method.strip(), args.repeats, args.timeout, tmp)
                rows.append(row)
                print(f"{row['scenario']} {method}: median {row['median']:.0f} ms",
                      file=sys.stderr, flush=True)
    text = table(rows)
    print(text)
    if args.out:
        args.out.write_text(text + '\n')
    return 0
