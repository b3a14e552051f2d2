"""Soak the planner node: drifting threats at 10 Hz for minutes, with recording on.

A planner node (method 'paper') records every input and output to a bag folder while this
suite publishes the scenario's threats (``test/data/uniform20_0.yaml`` by default) drifting
as a reflected random walk at ``--rate`` Hz for ``--minutes`` minutes, from a publisher with
the threat_publisher's QoS (reliable, transient local, depth ``--publisher-depth``). Once a
second it samples the node's RSS and times a parameter get. At the end the node is stopped
with SIGINT and the bag is read back strictly (it must be finished): every picture sent
must be in it, exactly once, by stamp.

The node's ``threats`` subscription keeps ``THREAT_INPUT.depth`` pictures (10): at 10 Hz
the executor may stall for up to 1 s before one is dropped unrecorded; the worst parameter
get time measures how long it actually stalls.

Usage::

    .venv/bin/python -m bench soak                  # 10 minutes
    .venv/bin/python -m bench soak --minutes 1 --out ''
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
import shutil
import signal
import sys
import tempfile
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from bench.toolkit.node import (cloud, domain_id, info, ParameterProbe, planner_command,
                                RosClient, scenario_params, STAMP0_NS, start_process)
from bench.toolkit.repo import DATA
from bench.toolkit.report import write_results
from bench.toolkit.timing import load_average, memory_summary, rss_kib, Sampler, stats
from threat_planner.bag import read_messages
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.ros.conversions import ns_to_stamp, stamp_to_ns
from threat_planner.ros.interface import THREAT_INPUT
from threat_planner.ros.publisher import ThreatDrift

DEFAULT_SCENARIO = DATA / 'uniform20_0.yaml'
MAX_GROWTH_PCT = 10.0


def soak(minutes: float, rate: float, scenario_path: Path, drift: float, depth: int,
         work: Path, method: str = 'paper', seed: int = 0) -> dict:
    """Run one soak; return the measurements.

    Parameters
    ----------
    minutes : float
        Length of the run [min].
    rate : float
        Threat pictures per second [Hz].
    scenario_path : Path
        Scenario file.
    drift : float
        Threat speed [m/s].
    depth : int
        History depth of the threat publisher.
    work : Path
        Folder for the node's log and bag.
    method : str
        Planner method.
    seed : int
        Seed of the drift.

    Returns
    -------
    dict
        Counts, RSS [MiB], parameter get times [ms], recording check, exit code.

    """
    scenario = load_scenario(scenario_path)
    box = scenario.box
    ns = '/soak'
    bags = work / 'bags'
    client = RosClient(domain_id(41, span=5), 'soak_bench')
    proc = start_process(planner_command(ns, scenario_params(
        scenario, method=method, record=str(bags))), client.domain, work / 'node.log')
    qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=depth)
    info_topic = f'{ns}/plan_info'
    sent: list[int] = []
    try:
        client.subscribe(info_topic, DiagnosticArray)
        pub = client.publisher(f'{ns}/threats', PointCloud2, qos)
        client.wait_matched(pub, timeout=30.0)
        probe = ParameterProbe(client, f'{ns}/threat_planner')
        if not probe.wait_ready(30.0):
            raise RuntimeError('parameter services of the node did not appear')
        moving = ThreatDrift(scenario.threats.positions, box.lo, box.hi, drift, seed=seed)
        # A first picture, answered, before the counted run: it proves both ends of the
        # topic are matched (the first samples of a new publisher can race discovery) and
        # keeps first-call costs (imports, the first service call) out of the figures.
        pub.publish(cloud(scenario.threats.positions, scenario.threats.intensities,
                          scenario.frame_id, ns_to_stamp(1)))
        client.wait_for(info_topic, lambda m: info(m)['input_stamp_ns'] == '1', 60.0)
        probe.get_ms()
        rss = Sampler(lambda: rss_kib(proc.pid)).start()
        gets = Sampler(probe.get_ms).start()
        period, n = 1.0 / rate, int(round(minutes * 60.0 * rate))
        t0 = time.monotonic()
        for k in range(n):
            delay = t0 + k * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            stamp_ns = STAMP0_NS + k * int(1e9 * period)
            positions = moving.at(k * period, period if k else 0.0)
            pub.publish(cloud(positions, scenario.threats.intensities, scenario.frame_id,
                              ns_to_stamp(stamp_ns)))
            sent.append(stamp_ns)
            if k % int(60 * rate) == 0:
                print(f'{k / rate / 60:.0f} min: RSS {rss_kib(proc.pid)} KiB', file=sys.stderr,
                      flush=True)
        t_end = time.monotonic()
        last = info(client.wait_for(
            info_topic, lambda m: int(info(m)['input_stamp_ns']) == sent[-1], 60.0))
        drain_s = time.monotonic() - t_end
        gets.stop()
        rss.stop()
        alive = proc.poll() is None
    finally:
        t_sig = time.monotonic()
        proc.send_signal(signal.SIGINT)
        try:
            code = proc.wait(30.0)
        except Exception:  # noqa: B902 - report a hung node as a failure, then kill it
            proc.kill()
            code = proc.wait(10.0)
        exit_s = time.monotonic() - t_sig
        client.close()
    infos = [info(m) for _, m in client.messages[info_topic]]
    bag_dirs = sorted(d for d in bags.iterdir() if d.is_dir())
    recorded = Counter()
    topics = Counter()
    read_error = None
    try:
        for m in read_messages(bag_dirs[0]):  # strict: the bag must be finished
            topics[m.topic] += 1
            if m.topic == f'{ns}/threats' and stamp_to_ns(m.msg.header.stamp) >= STAMP0_NS:
                recorded[stamp_to_ns(m.msg.header.stamp)] += 1
    except Exception as exc:  # noqa: B902 - report any reading failure
        read_error = f'{type(exc).__name__}: {exc}'
    missing = [s for s in sent if recorded[s] == 0]
    duplicated = [s for s, c in recorded.items() if c > 1]
    rss_values = rss.values()
    return {
        'scenario': scenario.name, 'threats': len(scenario.threats), 'method': method,
        'minutes': minutes, 'rate_hz': rate, 'drift_m_s': drift,
        'publisher_depth': depth, 'subscription_depth': THREAT_INPUT.depth,
        'subscription_slack_s': THREAT_INPUT.depth / rate,
        'inputs_sent': len(sent), 'inputs_received': int(last['inputs_received']) - 1,
        'inputs_skipped': int(last['inputs_skipped']),
        'plans_completed': int(last['plans_completed']) - 1,
        'errors': [i['message'] for i in infos if i['level'] == 'ERROR'],
        'last_plan_answers_last_input': int(last['input_stamp_ns']) == sent[-1],
        'drain_s': drain_s,
        'bag': str(bag_dirs[0]), 'bag_read_error': read_error,
        'bag_topics': dict(topics), 'inputs_in_bag': sum(recorded.values()),
        'inputs_missing_from_bag': len(missing), 'missing_indices': [
            round((s - STAMP0_NS) * rate / 1e9) for s in missing][:20],
        'inputs_duplicated_in_bag': len(duplicated),
        'rss': memory_summary(rss_values),
        'rss_after_1min': memory_summary(rss_values[60:]) if len(rss_values) > 120 else None,
        'param_get_ms': stats(gets.values()),
        'alive_after': alive, 'exit_code': code, 'sigint_exit_s': exit_s,
        'load_average': load_average(),
    }


def markdown(r: dict) -> str:
    """Return the Markdown summary of one soak."""
    mem, get = r['rss'], r['param_get_ms']
    lines = [
        f"### Soak: {r['threats']} drifting threats ({r['scenario']}, {r['drift_m_s']:g} m/s) "
        f"at {r['rate_hz']:g} Hz for {r['minutes']:g} min, recording on "
        f"(method {r['method']})",
        '',
        '| figure | value |',
        '|---|---:|',
        f"| inputs sent / received by the node / in the bag | {r['inputs_sent']} / "
        f"{r['inputs_received']} / {r['inputs_in_bag']} |",
        f"| inputs missing from the bag / duplicated | {r['inputs_missing_from_bag']} / "
        f"{r['inputs_duplicated_in_bag']} |",
        f"| bag read back strictly (finished) | "
        f"{'yes' if r['bag_read_error'] is None else r['bag_read_error']} |",
        f"| plans / inputs coalesced (skipped) / ERROR plan_info | {r['plans_completed']} / "
        f"{r['inputs_skipped']} / {len(r['errors'])} |",
        f"| last plan answers last input | {r['last_plan_answers_last_input']} |",
        f"| RSS start / end / max | {mem['start_mib']:.1f} / {mem['end_mib']:.1f} / "
        f"{mem['max_mib']:.1f} MiB |",
        f"| RSS growth end / max vs start | {mem['growth_pct']:+.1f} % / "
        f"{mem['max_growth_pct']:+.1f} % |",
    ]
    if r['rss_after_1min']:
        m1 = r['rss_after_1min']
        lines.append(f"| RSS growth end / max vs the 1-minute mark | {m1['growth_pct']:+.1f} % "
                     f"/ {m1['max_growth_pct']:+.1f} % |")
    lines += [
        f"| parameter get, median / p95 / max ({get['n']} probes) | {get['median']:.1f} / "
        f"{get['p95']:.1f} / {get['max']:.1f} ms |",
        f"| threats subscription depth (slack at {r['rate_hz']:g} Hz) / publisher depth | "
        f"{r['subscription_depth']} ({r['subscription_slack_s']:.1f} s) / "
        f"{r['publisher_depth']} |",
        f"| SIGINT -> exit / exit code | {1e3 * r['sigint_exit_s']:.0f} ms / "
        f"{r['exit_code']} |",
    ]
    if 'load_average' in r:
        lines.append(f"| host load average (1 min, at the end) | {r['load_average']:.1f} |")
    return '\n'.join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    """Run the soak and print (and write) the results."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=10.0, help='[Hz]')
    parser.add_argument('--scenario', type=Path, default=DEFAULT_SCENARIO)
    parser.add_argument('--drift', type=float, default=2.0, help='threat speed [m/s]')
    parser.add_argument('--publisher-depth', type=int, default=1)
    parser.add_argument('--method', default='paper')
    parser.add_argument('--keep', type=Path, help='copy the node log and bag here')
    parser.add_argument('--out', default='reliability_soak',
                        help="results stem under bench/results ('' = do not write)")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix='soak_') as tmp:
        result = soak(args.minutes, args.rate, args.scenario, args.drift,
                      args.publisher_depth, Path(tmp), args.method)
        if args.keep:
            shutil.copytree(tmp, args.keep, dirs_exist_ok=True)
    text = markdown(result)
    print(text)
    if args.out:
        write_results(args.out, result, text)
    ok = (result['inputs_missing_from_bag'] == 0 and result['bag_read_error'] is None
          and result['rss']['growth_pct'] <= MAX_GROWTH_PCT and result['exit_code'] == 0
          and result['last_plan_answers_last_input'])
    return 0 if ok else 1
