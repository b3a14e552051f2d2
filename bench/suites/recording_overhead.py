"""What recording costs the planner node: latency with and without MCAP recording, bytes.

For each scenario two planner nodes run side by side in one ROS domain (discovery on this
host only): one plain, one with parameter ``record`` set. Both get the same threat
pictures, alternately (plain, then recording, then the next picture), each moved by a
few centimetres so that it is a new one; the first picture of each is a warm-up. For each
picture the time from ``publish()`` to the arrival of ``path`` and of ``plan_info``
(matched by header stamp) is measured. The recording node writes the input cloud before
it plans and each output right after publishing it, so its ``path`` waits for the cloud
and ``initial_path`` to be written, its ``plan_info`` also for ``path`` and ``network``.

Then the recording is read back: file bytes per plan (zstd-compressed chunks, the
schemas and summary shared out) and serialised bytes per plan by topic; and the
messages of one plan are written again in this process, a plan per chunk (the node flushes
at least once a second), to time the write itself: CDR serialisation, chunking,
compression and the file write.

Usage::

    .venv/bin/python -m bench recording_overhead                  # 20 and 1000 threats
    .venv/bin/python -m bench recording_overhead --repeats 10 --method best
    .venv/bin/python -m bench recording_overhead --out bench/results/recording.md
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path
import statistics
import sys
import time

from builtin_interfaces.msg import Time
from mcap.reader import make_reader
import numpy as np
from sensor_msgs.msg import PointCloud2

from bench.toolkit.node import (cloud, jitter, planner_command, RosClient, ros_session,
                                round_trip, scenario_params, start_process, stop_process,
                                subscribe_answers)
from bench.toolkit.repo import DATA, RESULTS, SHARED
from threat_planner.bag import McapRecorder, read_ros_messages
from threat_planner.core.inputs.scenario import load_scenario

DEFAULT_SCENARIOS = (DATA / 'uniform20_0.yaml', SHARED / 'scale1000.yaml')
DEFAULT_OUT = RESULTS / 'recording.md'


def _file_stats(path: Path) -> dict:
    """Return plans, file bytes and serialised bytes per topic of a finished recording."""
    per_topic = collections.Counter()
    with open(path, 'rb') as f:
        reader = make_reader(f)
        for _, channel, message in reader.iter_messages():
            per_topic[channel.topic.rsplit('/', 1)[-1]] += len(message.data)
        summary = reader.get_summary()
    counts = {summary.channels[cid].topic.rsplit('/', 1)[-1]: n
              for cid, n in summary.statistics.channel_message_counts.items()}
    return {'plans': counts.get('plan_info', 0), 'file_bytes': path.stat().st_size,
            'serialised': per_topic}


def _write_ms(path: Path, out: Path, repeats: int) -> float:
    """Return the median time [ms] to write one plan's messages (a chunk) to a recording."""
    messages = list(read_ros_messages(path))
    last_cloud = max(i for i, m in enumerate(messages) if m.topic.endswith('/threats'))
    plan_msgs = [m for m in messages[last_cloud:]
                 if m.topic.rsplit('/', 1)[-1] in ('threats', 'initial_path', 'path',
                                                   'network', 'plan_info')]
    times = []
    with McapRecorder(out, flush_interval_s=None) as rec:
        for m in plan_msgs:
            rec.add_topic(m.topic, m.type_name)
        for _ in range(repeats):
            t0 = time.perf_counter()
            for m in plan_msgs:
                rec.write(m.topic, m.msg, log_time_ns=m.log_time_ns)
            rec.flush()
            times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


def measure(client: RosClient, scenario_path: Path, method: str, repeats: int,
            timeout: float, work: Path) -> dict:
    """Run the plain and the recording node on one scenario; return the statistics."""
    scenario = load_scenario(scenario_path)
    n = len(scenario.threats)
    params = scenario_params(scenario, method=method)
    record = work / f'rec_{n}.mcap'
    nodes = {}
    try:
        for kind, extra in (('plain', {}), ('rec', {'record': str(record)})):
            ns = f'/{kind}_{n}'
            nodes[kind] = (ns, start_process(planner_command(ns, {**params, **extra}),
                                             client.domain, work / f'{kind}_{n}.log'))
            subscribe_answers(client, ns)
        for ns, _ in nodes.values():
            client.wait_matched(client.publisher(f'{ns}/threats', PointCloud2), timeout=30.0)
        rng = np.random.default_rng(0)
        samples = {kind: [] for kind in nodes}
        for run in range(repeats + 1):
            msg = cloud(jitter(scenario.threats.positions, rng), scenario.threats.intensities,
                        scenario.frame_id, Time(sec=1000 + run))
            # Alternate who goes first, so that neither always follows the other's work.
            order = list(nodes.items())[::1 if run % 2 else -1]
            for kind, (ns, _) in order:
                path_ms, info_ms, values = round_trip(client, ns, msg, timeout)
                if run:  # the first picture warms up imports and caches
                    samples[kind].append((path_ms, info_ms, float(values['plan_wall_ms'])))
    finally:
        for ns, proc in nodes.values():
            stop_process(proc)
            client.unsubscribe(f'{ns}/path')
            client.unsubscribe(f'{ns}/plan_info')
    stats = _file_stats(record)
    row = {'scenario': scenario.name, 'threats': n, 'method': method, 'runs': repeats,
           'write_ms': _write_ms(record, work / f'rewrite_{n}.mcap', max(repeats, 5)),
           **stats}
    for kind, values in samples.items():
        path_ms, info_ms, plan_ms = (np.array(v) for v in zip(*values))
        row[f'{kind}_plan'] = float(np.median(plan_ms))
        # Latency less the node's own planning time: the planning time varies from run
        # to run by more than recording costs, and recording does not change it.
        row[f'{kind}_path'] = float(np.median(path_ms - plan_ms))
        row[f'{kind}_info'] = float(np.median(info_ms - plan_ms))
    return row


def table(rows: list[dict]) -> str:
    """Return the Markdown tables: latency side by side, then bytes per plan."""
    lines = ['| scenario | threats | method | runs | plan: plain / recording [ms] | '
             'to path less plan: plain [ms] | recording [ms] | +[ms] | '
             'to plan_info less plan: plain [ms] | recording [ms] | +[ms] | '
             'write one plan [ms] |',
             '|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|']
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['threats']} | {r['method']} | {r['runs']} | "
            f"{r['plain_plan']:.0f} / {r['rec_plan']:.0f} | {r['plain_path']:.1f} | "
            f"{r['rec_path']:.1f} | "
            f"{r['rec_path'] - r['plain_path']:+.1f} | {r['plain_info']:.1f} | "
            f"{r['rec_info']:.1f} | {r['rec_info'] - r['plain_info']:+.1f} | "
            f"{r['write_ms']:.1f} |")
    lines += ['', '| scenario | threats | plans in file | file size [KiB] | file bytes per plan '
              '| serialised bytes per plan: threats | initial_path + path | network | '
              'plan_info |',
              '|---|---:|---:|---:|---:|---:|---:|---:|---:|']
    for r in rows:
        plans = max(r['plans'], 1)
        s = r['serialised']
        lines.append(
            f"| {r['scenario']} | {r['threats']} | {r['plans']} | "
            f"{r['file_bytes'] / 1024:.0f} | {r['file_bytes'] / plans:,.0f} | "
            f"{s['threats'] / plans:,.0f} | {(s['initial_path'] + s['path']) / plans:,.0f} | "
            f"{s['network'] / plans:,.0f} | {s['plan_info'] / plans:,.0f} |")
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the measurement and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('scenarios', nargs='*', type=Path, default=list(DEFAULT_SCENARIOS))
    parser.add_argument('--method', default='paper', help="planner method (default 'paper')")
    parser.add_argument('--repeats', type=int, default=10, help='timed pictures per node')
    parser.add_argument('--timeout', type=float, default=600.0, help='per plan [s]')
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT, help='Markdown report')
    args = parser.parse_args(argv)

    rows = []
    session = ros_session(89, 2, 'recording_overhead_bench', 'recording_overhead_')
    with session as (client, tmp):
        for path in args.scenarios:
            rows.append(measure(client, path, args.method, args.repeats, args.timeout, tmp))
            print(f'{rows[-1]["scenario"]}: done', file=sys.stderr, flush=True)
    text = ('# Recording overhead\n\nMeasured by `python -m bench recording_overhead` (see '
            f'bench/suites/recording_overhead.py): medians over {args.repeats} threat '
            'pictures per node after one warm-up; "+" is the recording node minus the plain '
            'one, measured in the same run, alternately; "less plan" is the latency minus '
            'the node\'s planning time (`plan_wall_ms`). "write one plan" is the in-process '
            'time to write the messages of one plan (threats, initial_path, path, network, '
            'plan_info) as one chunk.\n\n' + table(rows) + '\n')
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    return 0
