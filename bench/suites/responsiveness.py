"""Is the node responsive during a long plan? Parameter-get latency, and exit on SIGTERM.

For each (threats, n_points): a fresh planner node ('best') gets one threat picture; while
it plans, this process calls ``get_parameters`` every 50 ms and records each round trip;
once the plan is answered (or after ``--window`` s) a SIGTERM is sent and the time to exit
is measured. Writes ``bench/results/responsiveness.md`` (append a dated section).

Usage: ``python -m bench responsiveness --threats 20 --n-points 40 200 1000 --label after``
"""

from __future__ import annotations

import argparse
import datetime
from pathlib import Path
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import PointCloud2

from bench.toolkit.cases import random_scenario
from bench.toolkit.node import (cloud, info, planner_command, RosClient, ros_session,
                                scenario_params, start_process)
from bench.toolkit.repo import RESULTS
from bench.toolkit.report import append_section, md_table


def measure(client: RosClient, threats: int, n_points: int, window: float,
            log: Path, extra: dict) -> dict:
    """Return the parameter gets [ms] during one plan and the SIGTERM exit time [s]."""
    scenario = random_scenario(threats)
    ns = f'/resp_{threats}_{n_points}'
    params = scenario_params(scenario, frame=False, n_points=n_points,
                             max_threats=max(threats, 10), **extra)
    proc = start_process(planner_command(ns, params), client.domain, log)
    client.subscribe(f'{ns}/plan_info', DiagnosticArray)
    pub = client.publisher(f'{ns}/threats', PointCloud2)
    client.wait_matched(pub, timeout=60.0)
    params_client = AsyncParameterClient(client.node, f'{ns}/threat_planner')
    assert params_client.wait_for_services(timeout_sec=30.0)
    pub.publish(cloud(scenario.threats.positions, scenario.threats.intensities))
    latencies, answered, t0 = [], None, time.monotonic()
    while time.monotonic() - t0 < window:
        t = time.monotonic()
        future = params_client.get_parameters(['w'])
        while not future.done() and time.monotonic() - t < window:
            time.sleep(0.001)
        latencies.append(1e3 * (time.monotonic() - t))
        if client.count(f'{ns}/plan_info'):
            answered = info(client.last(f'{ns}/plan_info'))
            break
        time.sleep(0.05)
    t = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        code = proc.wait(30)
    except Exception:  # noqa: B902 - record a node that does not exit as such
        proc.kill()
        code = proc.wait(5)
    exit_s = time.monotonic() - t
    lat = np.array(latencies)
    return {'threats': threats, 'n_points': n_points, 'probes': len(lat),
            'p50_ms': float(np.percentile(lat, 50)), 'p95_ms': float(np.percentile(lat, 95)),
            'max_ms': float(lat.max()), 'plan_s': time.monotonic() - t0 - exit_s,
            'answered': None if answered is None else answered['level'] + ' ' +
            answered['message'][:60], 'exit_s': exit_s, 'exit_code': code}


def main(argv: list[str] | None = None) -> int:
    """Run the measurements and append them to the results file."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--threats', type=int, nargs='+', default=[20])
    ap.add_argument('--n-points', type=int, nargs='+', default=[40, 200, 1000])
    ap.add_argument('--window', type=float, default=60.0, help='longest wait per plan [s]')
    ap.add_argument('--label', default='')
    ap.add_argument('--max-plan-time', type=float, default=None)
    ap.add_argument('--out', type=Path, default=RESULTS / 'responsiveness.md')
    args = ap.parse_args(argv)
    extra = {} if args.max_plan_time is None else {'max_plan_time_s': args.max_plan_time}
    rows = []
    with ros_session(81, 40, 'responsiveness_bench') as (client, _):
        for threats in args.threats:
            for n in args.n_points:
                r = measure(client, threats, n, args.window, Path(f'/tmp/resp_{n}.log'), extra)
                print(r, flush=True)
                rows.append(r)
    table = md_table(['threats', 'n_points', 'probes', 'p50 [ms]', 'p95 [ms]', 'max [ms]',
                      'plan [s]', 'SIGTERM exit [s]', 'answer'],
                     ([r['threats'], r['n_points'], r['probes'], f"{r['p50_ms']:.1f}",
                       f"{r['p95_ms']:.1f}", f"{r['max_ms']:.1f}", f"{r['plan_s']:.1f}",
                       f"{r['exit_s']:.2f} (rc {r['exit_code']})", r['answered']]
                      for r in rows))
    append_section(args.out, f'{args.label} ({datetime.date.today().isoformat()}, shared '
                   '2-core machine)', table)
    return 0
