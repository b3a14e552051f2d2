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

    .venv/bin/python bench/node_latency.py                      # 20, 300, 1000 threats
    .venv/bin/python bench/node_latency.py --methods paper --repeats 5
    .venv/bin/python bench/node_latency.py --out bench/results/node_latency.md
"""

from __future__ import annotations

import argparse
from pathlib import Path
import statistics
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'test'))
sys.path.insert(0, str(REPO))

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from node_harness import (cloud, domain_id, info, planner_command, RosClient,  # noqa: E402
                          start_process, stop_process)
import numpy as np  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402

from threat_planner.ros.conversions import stamp_to_ns  # noqa: E402
from threat_planner.core.inputs.scenario import load_scenario  # noqa: E402

DEFAULT_SCENARIOS = (REPO / 'test' / 'data' / 'uniform20_0.yaml',
                     REPO / 'test' / 'data' / 'big300_0.yaml',
                     Path('/work/shared/scenarios/scale1000.yaml'))


def measure(client: RosClient, scenario_path: Path, method: str, repeats: int,
            timeout: float, log_dir: Path) -> dict:
    """Start a node for one scenario and method; return its latency statistics [ms]."""
    scenario = load_scenario(scenario_path)
    ns = f'/bench_{method}_{len(scenario.threats)}'
    params = {'method': method, 'bounds': scenario.box.lo.tolist() + scenario.box.hi.tolist(),
              'start': scenario.start.tolist(), 'goal': scenario.goal.tolist(),
              'frame_id': scenario.frame_id}
    proc = start_process(planner_command(ns, params), client.domain,
                         log_dir / f'{ns.strip("/")}.log')
    latencies, plan_ms, messages_ms = [], [], []
    try:
        client.subscribe(f'{ns}/path', PathMsg)
        client.subscribe(f'{ns}/plan_info', DiagnosticArray)
        pub = client.publisher(f'{ns}/threats', PointCloud2)
        client.wait_matched(pub, timeout=30.0)
        rng = np.random.default_rng(0)
        for run in range(repeats + 1):
            positions = scenario.threats.positions + rng.normal(scale=0.05, size=(
                len(scenario.threats), 3))
            stamp = Time(sec=1000 + run)
            msg = cloud(positions, scenario.threats.intensities, scenario.frame_id, stamp)
            t0 = time.perf_counter()
            pub.publish(msg)
            client.wait_for(f'{ns}/path', lambda m: m.header.stamp == stamp, timeout)
            latency = 1e3 * (time.perf_counter() - t0)
            values = info(client.wait_for(
                f'{ns}/plan_info', lambda m: m.header.stamp == stamp, timeout))
            if values['level'] == 'ERROR':
                raise RuntimeError(f'{scenario_path.name}: {values["message"]}')
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
    """Markdown table of the measurements."""
    lines = ['| scenario | threats | method | runs | latency median [ms] | min [ms] | '
             'max [ms] | plan [ms] | node + transport [ms] | markers [ms] |',
             '|---|---:|---|---:|---:|---:|---:|---:|---:|---:|']
    for r in rows:
        lines.append(f"| {r['scenario']} | {r['threats']} | {r['method']} | {r['runs']} | "
                     f"{r['median']:.0f} | {r['min']:.0f} | {r['max']:.0f} | "
                     f"{r['plan']:.0f} | {r['overhead']:.1f} | {r['messages']:.1f} |")
    return '\n'.join(lines)


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

    client = RosClient(domain_id(91, span=10), 'node_latency_bench')
    rows = []
    try:
        with tempfile.TemporaryDirectory(prefix='node_latency_') as tmp:
            for path in args.scenarios:
                for method in args.methods.split(','):
                    row = measure(client, path, method.strip(), args.repeats, args.timeout,
                                  Path(tmp))
                    rows.append(row)
                    print(f"{row['scenario']} {method}: median {row['median']:.0f} ms",
                          file=sys.stderr, flush=True)
    finally:
        client.close()
    text = table(rows)
    print(text)
    if args.out:
        args.out.write_text(text + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
