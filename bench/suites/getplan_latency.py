"""GetPlan round-trip latency of a planner node in another process, and its topic replans.

For each threat count: a fresh planner node (default parameters, method 'best') gets one
random threat picture; after its topic plan and one warm-up request, ``plan_path`` is
called ``--calls`` times one after another (start and goal moved a little each time) and
each round trip is timed in this process. Then the start is moved ``--calls`` times on the
``start`` topic and each replan's ``plan_info`` (``start`` warm/cold, ``total_ms``) is read.
Appends a dated section to ``bench/results/getplan.md``.

Usage: ``python -m bench getplan_latency --threats 20 1000 --calls 5``
"""

from __future__ import annotations

import argparse
import datetime
import os
from pathlib import Path
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.srv import GetPlan
import numpy as np
from sensor_msgs.msg import PointCloud2

from bench.toolkit.cases import random_scenario
from bench.toolkit.checkouts import short_commit
from bench.toolkit.node import (cloud, info, planner_command, pose, RosClient, ros_session,
                                scenario_params, start_process, stop_process, VOLATILE)
from bench.toolkit.repo import RESULTS, ROOT
from bench.toolkit.report import append_section, md_table


def measure(client: RosClient, threats: int, calls: int, log: Path) -> dict:
    """Return the round trips [ms] of GetPlan calls and the replans' plan_info of a node."""
    scenario = random_scenario(threats)
    ns = f'/getplan_{threats}'
    s0, g0 = scenario.start, scenario.goal
    params = scenario_params(scenario, frame=False, max_threats=max(threats, 10))
    proc = start_process(planner_command(ns, params), client.domain, log)
    try:
        topic = f'{ns}/plan_info'
        client.subscribe(topic, DiagnosticArray)
        pub = client.publisher(f'{ns}/threats', PointCloud2)
        start_pub = client.publisher(f'{ns}/start', PoseStamped, VOLATILE)
        client.wait_matched(pub, timeout=60.0)
        client.wait_matched(start_pub, timeout=60.0)
        pub.publish(cloud(scenario.threats.positions, scenario.threats.intensities))
        first = info(client.wait_for(topic, timeout=300.0))
        cli = client.node.create_client(GetPlan, f'{ns}/plan_path')
        assert cli.wait_for_service(timeout_sec=30.0)
        round_trips, poses = [], []
        for i in range(calls + 1):   # the first call is the warm-up, not counted
            shift = np.array([0.0, 0.0, 0.5 * i])
            req = GetPlan.Request(start=pose((s0 + shift).tolist()),
                                  goal=pose((g0 - shift).tolist()))
            t = time.monotonic()
            # woken by the answer itself: polling future.done put every round trip on a
            # 20 ms grid (41, 61, 81 ms in getplan.md before this)
            answer = client.wait_future(cli.call_async(req), 300.0, 'plan_path answer')
            if i:
                round_trips.append(1e3 * (time.monotonic() - t))
                poses.append(len(answer.plan.poses))
        replans = []
        for i in range(1, calls + 1):
            count = client.count(topic)
            moved = s0 + np.array([0.0, 0.0, 0.5 * i])
            stamp_sec = 100 + i
            msg = pose(moved.tolist())
            msg.header.stamp.sec = stamp_sec
            start_pub.publish(msg)
            got = info(client.wait_for(
                topic, lambda m, s=stamp_sec: info(m)['input_stamp_ns'] == str(s * 10**9),
                after=count, timeout=300.0))
            replans.append((got.get('start', '?'), float(got.get('total_ms', 'nan')),
                            float(got.get('plan_wall_ms', 'nan'))))
    finally:
        code = stop_process(proc, signal.SIGTERM)
    rt = np.array(round_trips)
    return {'threats': threats, 'calls': calls, 'first_plan_ms': float(first['plan_wall_ms']),
            'median_ms': float(np.median(rt)), 'min_ms': float(rt.min()),
            'max_ms': float(rt.max()), 'poses': sorted(set(poses)), 'replans': replans,
            'exit_code': code}


def main(argv: list[str] | None = None) -> int:
    """Run the measurements and append them to the results file."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--threats', type=int, nargs='+', default=[20, 1000])
    ap.add_argument('--calls', type=int, default=5)
    ap.add_argument('--label', default=None, help='section title (default: the commit)')
    ap.add_argument('--out', type=Path, default=RESULTS / 'getplan.md')
    args = ap.parse_args(argv)
    rows = []
    with ros_session(91, 40, 'getplan_bench') as (client, _):
        for n in args.threats:
            r = measure(client, n, args.calls, Path(f'/tmp/getplan_{n}.log'))
            print(r, flush=True)
            rows.append(r)
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    table = md_table(['threats', 'calls', 'GetPlan median [ms]', 'min [ms]', 'max [ms]',
                      'poses', 'first topic plan [ms]', 'topic replans (start, total_ms)'],
                     ([r['threats'], r['calls'], f"{r['median_ms']:.0f}", f"{r['min_ms']:.0f}",
                       f"{r['max_ms']:.0f}", r['poses'], f"{r['first_plan_ms']:.0f}",
                       '; '.join(f'{s} {t:.0f}' for s, t, _ in r['replans'])] for r in rows))
    label = short_commit(ROOT) if args.label is None else args.label
    append_section(args.out, f'{label} ({datetime.datetime.utcnow():%Y-%m-%d %H:%M} UTC, '
                   f'shared 2-core machine, load average {load} at the end)', table)
    return 0
