"""Flood the planner node with threat updates and check that it keeps up without a backlog.

A planner node is started as its own process (method 'paper', discovery limited to this
host) and sent ``--threats`` threats (``test/data/big300_0.yaml``, every picture jittered by
a few centimetres so that each one is new) at ``--rate`` Hz for ``--seconds`` s. Meanwhile,
once a second, this suite

* times a parameter get against the node (the executor must stay responsive: < 100 ms),
* samples the node's resident memory (``VmRSS`` in ``/proc/<pid>/status``).

Every ``plan_info`` that arrives is matched by its ``input_stamp_ns`` to the picture it
answers; the lag is the time from that picture's ``publish()`` to the arrival of its
``plan_info``. After the flood stops, the last plan must answer the last picture (the node
coalesces updates, latest wins) and arrive within a couple of plan times (no queue).

Usage::

    .venv/bin/python -m bench flood                      # 60 s at 100 Hz, 300 threats
    .venv/bin/python -m bench flood --seconds 10 --out ''

``test/ros/test_node_faults.py`` runs :func:`run_flood` at CI size.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import signal
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Path as PathMsg
import numpy as np
from sensor_msgs.msg import PointCloud2

from bench.toolkit.node import (cloud, info, jitter, LATCHED_LOG, ParameterProbe,
                                planner_command, RosClient, ros_session, scenario_params,
                                STAMP0_NS, start_process, stop_process)
from bench.toolkit.repo import DATA
from bench.toolkit.report import write_results
from bench.toolkit.timing import load_average, memory_summary, rss_kib, Sampler, stats
from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.ros.conversions import ns_to_stamp, stamp_to_ns

DEFAULT_SCENARIO = DATA / 'big300_0.yaml'


def run_flood(client: RosClient, scenario: Scenario, rate: float, seconds: float,
              log_path: Path, ns: str = '/flood', method: str = 'paper',
              n_points: int = 20, threats: Optional[int] = None, seed: int = 0) -> dict:
    """Start a node, flood it, stop it; return the measurements.

    Parameters
    ----------
    client : RosClient
        Client in the node's domain.
    scenario : Scenario
        Threats, bounds, start and goal.
    rate : float
        Threat pictures per second [Hz].
    seconds : float
        Length of the flood [s].
    log_path : Path
        Node's log file.
    ns : str
        Namespace of the node.
    method : str
        Planner method.
    n_points : int
        Chain segments of the final path.
    threats : int, optional
        Use only the first this many threats of the scenario.
    seed : int
        Seed of the jitter.

    Returns
    -------
    dict
        Inputs sent and received, plans, lags [ms], parameter get times [ms], RSS [MiB],
        whether the last plan answers the last input, and the node's exit code.

    """
    positions0 = scenario.threats.positions[:threats]
    intensities = scenario.threats.intensities[:threats]
    proc = start_process(planner_command(ns, scenario_params(
        scenario, method=method, n_points=n_points)), client.domain, log_path)
    info_topic, path_topic = f'{ns}/plan_info', f'{ns}/path'
    client.subscribe(info_topic, DiagnosticArray)
    client.subscribe(path_topic, PathMsg)
    # Latched as a threat source is, but every picture kept until the node acknowledges it
    # (depth 100 = 1 s at 100 Hz): at depth 1 a picture that the next one replaced before a
    # busy machine delivered it was lost in this process, and counted against the node.
    pub = client.publisher(f'{ns}/threats', PointCloud2, LATCHED_LOG)
    probe = ParameterProbe(client, f'{ns}/threat_planner')
    rng = np.random.default_rng(seed)
    sent_at: dict[int, float] = {}
    try:
        client.wait_matched(pub, timeout=30.0)
        if not probe.wait_ready(30.0):
            raise RuntimeError('parameter services of the node did not appear')
        # Warm up (imports, first-call caches) so that the flood measures steady state.
        pub.publish(cloud(positions0, intensities, scenario.frame_id, ns_to_stamp(1)))
        client.wait_for(info_topic, lambda m: info(m)['input_stamp_ns'] == '1', 60.0)
        time.sleep(1.0)
        rss = Sampler(lambda: rss_kib(proc.pid)).start()
        gets = Sampler(probe.get_ms).start()
        period, n = 1.0 / rate, int(round(seconds * rate))
        t0 = time.monotonic()
        for k in range(n):
            delay = t0 + k * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            stamp_ns = STAMP0_NS + k * 10**6  # input k: k ms on (unique, sortable)
            msg = cloud(jitter(positions0, rng), intensities, scenario.frame_id,
                        ns_to_stamp(stamp_ns))
            sent_at[stamp_ns] = time.monotonic()
            pub.publish(msg)
        t_end = time.monotonic()
        last_ns = STAMP0_NS + (n - 1) * 10**6
        last = client.wait_for(info_topic,
                               lambda m: int(info(m)['input_stamp_ns']) == last_ns, 60.0)
        drain_s = time.monotonic() - t_end
        time.sleep(1.0)  # would show any plan published after the last input's
        gets.stop()
        rss.stop()
        alive = proc.poll() is None
        answered = [(t, info(m)) for t, m in list(client.messages[info_topic])
                    if int(info(m)['input_stamp_ns']) >= STAMP0_NS]
        final_path = client.last(path_topic)
    finally:
        code = stop_process(proc, signal.SIGINT)
    plans = [(t, i) for t, i in answered if i['level'] != 'ERROR']
    errors = [i['message'] for _, i in answered if i['level'] == 'ERROR']
    lags = [1e3 * (t - sent_at[int(i['input_stamp_ns'])]) for t, i in plans]
    plan_ms = [float(i['plan_wall_ms']) for _, i in plans]
    behind = [sum(1 for s in sent_at.values() if s <= t) - 1
              - (int(i['input_stamp_ns']) - STAMP0_NS) // 10**6 for t, i in plans]
    flood_plans = [t for t, _ in plans if t <= t_end]
    last_info = info(last)
    received = int(last_info['inputs_received']) - 1  # minus the warm-up picture
    return {
        'threats': len(positions0), 'rate_hz': rate, 'seconds': seconds, 'method': method,
        'n_points': n_points, 'inputs_sent': n, 'achieved_send_rate_hz': n / (t_end - t0),
        'inputs_received': received,
        'inputs_skipped': int(last_info['inputs_skipped']),
        'inputs_rejected': int(last_info['inputs_rejected']),
        'plans_completed': int(last_info['plans_completed']) - 1,  # the node's count
        'plans_observed': len(plans), 'errors': errors,
        'plan_rate_hz': len(flood_plans) / (t_end - t0),
        'lag_ms': stats(lags), 'plan_wall_ms': stats(plan_ms),
        'inputs_behind': stats(behind),
        'last_plan_answers_last_input': bool(plans)
        and int(plans[-1][1]['input_stamp_ns']) == last_ns
        and stamp_to_ns(final_path.header.stamp) == int(plans[-1][1]['t0_ns']),
        'drain_s': drain_s,
        # Every input received was planned, coalesced away or refused: nothing queued.
        'accounted': received == (int(last_info['plans_completed']) - 1
                                  + int(last_info['inputs_skipped'])
                                  + int(last_info['inputs_rejected'])),
        'param_get_ms': stats(gets.values()),
        'param_get_timeouts': sum(1 for v in gets.values() if v == float('inf')),
        'rss': memory_summary(rss.values()),
        'alive_after': alive, 'exit_code': code, 'load_average': load_average(),
    }


def markdown(r: dict) -> str:
    """Return the Markdown summary of one flood."""
    lag, get, mem = r['lag_ms'], r['param_get_ms'], r['rss']
    return '\n'.join([
        f"### Flood: {r['threats']} threats at {r['rate_hz']:g} Hz for {r['seconds']:g} s "
        f"(method {r['method']}, n_points {r['n_points']})",
        '',
        '| figure | value |',
        '|---|---:|',
        f"| inputs sent / received by the node | {r['inputs_sent']} / "
        f"{r['inputs_received']} |",
        f"| achieved send rate | {r['achieved_send_rate_hz']:.1f} Hz |",
        f"| plans published / inputs coalesced (skipped) | {r['plans_completed']} / "
        f"{r['inputs_skipped']} |",
        f"| plan rate during the flood | {r['plan_rate_hz']:.2f} Hz |",
        f"| planner time per plan, median / p95 / max | {r['plan_wall_ms']['median']:.0f} / "
        f"{r['plan_wall_ms']['p95']:.0f} / {r['plan_wall_ms']['max']:.0f} ms |",
        f"| lag publish -> plan_info, median / p95 / max | {lag['median']:.0f} / "
        f"{lag['p95']:.0f} / {lag['max']:.0f} ms |",
        f"| newer inputs already sent when a plan arrived, median / max | "
        f"{r['inputs_behind']['median']:.0f} / {r['inputs_behind']['max']:.0f} |",
        f"| last plan answers last input | {r['last_plan_answers_last_input']} |",
        f"| received = planned + coalesced + refused | {r['accounted']} |",
        f"| last input -> its plan after the flood stopped | {1e3 * r['drain_s']:.0f} ms |",
        f"| parameter get, median / p95 / max ({get['n']} probes, 1 Hz) | "
        f"{get['median']:.1f} / {get['p95']:.1f} / {get['max']:.1f} ms |",
        f"| RSS start / end / max | {mem['start_mib']:.1f} / {mem['end_mib']:.1f} / "
        f"{mem['max_mib']:.1f} MiB |",
        f"| RSS growth end / max vs start | {mem['growth_pct']:+.1f} % / "
        f"{mem['max_growth_pct']:+.1f} % |",
        f"| node alive, exit code after SIGINT | {r['alive_after']}, {r['exit_code']} |",
        f"| host load average (1 min, at the end; {os.cpu_count()} CPUs) | "
        f"{r['load_average']:.1f} |",
    ])


def main(argv: Optional[list[str]] = None) -> int:
    """Run the flood and print (and write) the results."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', type=Path, default=DEFAULT_SCENARIO)
    parser.add_argument('--rate', type=float, default=100.0, help='[Hz]')
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--threats', type=int, help='use only the first N threats')
    parser.add_argument('--method', default='paper')
    parser.add_argument('--n-points', type=int, default=20)
    parser.add_argument('--out', default='reliability_flood',
                        help="results stem under bench/results ('' = do not write)")
    args = parser.parse_args(argv)

    scenario = load_scenario(args.scenario)
    with ros_session(86, 5, 'flood_bench', 'flood_') as (client, tmp):
        result = run_flood(client, scenario, args.rate, args.seconds, tmp / 'node.log',
                           method=args.method, n_points=args.n_points, threats=args.threats)
    result['scenario'] = scenario.name
    text = markdown(result)
    print(text)
    if args.out:
        write_results(args.out, result, text)
    ok = (result['last_plan_answers_last_input'] and result['param_get_ms']['max'] < 100.0
          and result['exit_code'] == 0 and not result['errors'])
    return 0 if ok else 1
