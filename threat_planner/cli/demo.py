"""The live demo: planner_node and threat_publisher side by side, plans printed as they come.

    threat_planner_demo [--scenario FILE] [--rate 1.0] [--drift 1.0] [--duration S]
                        [--figure demo_out/last_plan.png] [--method best]

Starts ``planner_node`` with ``config/planner.yaml`` and ``threat_publisher`` on the
scenario (its threats drifting, so the planner replans), both as child processes exactly as
``ros2 run`` would, and listens itself on ``plan_info``, ``path`` and ``threats``. Every
plan's J and timing is printed as it arrives. Ctrl-C (or ``--duration``) stops the children
with SIGINT, waits for them, and writes the figure of the last plan.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

from threat_planner.errors import ThreatPlannerError

PACKAGE_DIR = Path(__file__).resolve().parent
DEFAULT_SCENARIO = PACKAGE_DIR.parent / 'test' / 'data' / 'uniform20_0.yaml'
DEFAULT_PARAMS = PACKAGE_DIR.parent / 'config' / 'planner.yaml'


def _ros_args(params: dict[str, object]) -> list[str]:
    out = ['--ros-args']
    for key, value in params.items():
        text = str(value).lower() if isinstance(value, bool) else str(value)
        out += ['-p', f'{key}:={text}']
    return out


def _children(args: argparse.Namespace) -> list[subprocess.Popen]:
    """Start the planner and the publisher as ``ros2 run`` would start them."""
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    planner = [sys.executable, '-m', 'threat_planner.ros.entry', 'planner_node', '--ros-args']
    if Path(args.params).exists():
        planner += ['--params-file', str(args.params)]
    planner += _ros_args({'method': args.method})[1:]
    publisher = [sys.executable, '-m', 'threat_planner.ros.publisher'] + _ros_args(
        {'scenario': str(args.scenario), 'rate': float(args.rate),
         'drift': float(args.drift)})
    return [subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True) for cmd in (planner, publisher)]


def _stop(children: list[subprocess.Popen]) -> None:
    for child in children:
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
    for child in children:
        try:
            child.wait(timeout=10)
        except subprocess.TimeoutExpired:
            child.kill()


def run(args: argparse.Namespace) -> int:
    """Run the demo until Ctrl-C or ``args.duration``; return the exit status."""
    import numpy as np
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Path as PathMsg
    from sensor_msgs.msg import PointCloud2

    from threat_planner.ros.conversions import (path_from_msg, plan_info_values,
                                                threats_from_pointcloud2)
    from threat_planner.ros.discovery import apply_discovery_profile
    from threat_planner.cli.figures import plot_plan
    from threat_planner.core.inputs.scenario import load_scenario
    from threat_planner.core.world.threats import ThreatField

    scenario = load_scenario(args.scenario)
    latched = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         history=HistoryPolicy.KEEP_LAST, depth=1)
    state: dict[str, object] = {'plans': 0}
    lock = threading.Lock()
    children = _children(args)
    exit_code = 0
    try:
        apply_discovery_profile()
        rclpy.init(args=[])
        node = rclpy.create_node('threat_planner_demo')

        def on_info(msg: DiagnosticArray) -> None:
            v = plan_info_values(msg)
            if not msg.status:
                return
            status = msg.status[0]
            if status.level == status.ERROR:
                print(f'plan_info ERROR: {status.message}', flush=True)
                return
            if 'J' not in v:
                return
            with lock:
                state['plans'] = int(state['plans']) + 1
                n = state['plans']
            print(f'plan {n:3d} (input {v.get("input_seq", "?")}): J={float(v["J"]):.2f} '
                  f'J_L={float(v.get("J_L", "nan")):.2f} J_R={float(v.get("J_R", "nan")):.2f} '
                  f'plan {float(v.get("total_ms", "nan")):.0f} ms, '
                  f'{v.get("nodes", "?")} nodes, feasible={v.get("feasible", "?")}',
                  flush=True)

        def on_path(msg: PathMsg) -> None:
            with lock:
                state['path'] = path_from_msg(msg)

        def on_threats(msg: PointCloud2) -> None:
            try:
                with lock:
                    state['threats'] = threats_from_pointcloud2(msg, scenario.frame_id)
            except ThreatPlannerError:
                pass

        node.create_subscription(DiagnosticArray, 'plan_info', on_info, latched)
        node.create_subscription(PathMsg, 'path', on_path, latched)
        node.create_subscription(PathMsg, 'initial_path',
                                 lambda m: state.__setitem__('initial', path_from_msg(m)),
                                 latched)
        node.create_subscription(PointCloud2, 'threats', on_threats, latched)
        print(f'planner_node + threat_publisher on {scenario.name} '
              f'(rate {args.rate} Hz, drift {args.drift} m/s); Ctrl-C stops', flush=True)
        deadline = None if args.duration is None else time.monotonic() + args.duration
        while rclpy.ok() and (deadline is None or time.monotonic() < deadline):
            rclpy.spin_once(node, timeout_sec=0.2)
            dead = [c for c in children if c.poll() is not None]
            if dead:
                err = dead[0].stderr.read().strip().splitlines()
                print(f'a child exited early: {err[-1] if err else dead[0].returncode}',
                      file=sys.stderr)
                exit_code = 1
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        _stop(children)
        rclpy.try_shutdown()
    with lock:
        path, initial = state.get('path'), state.get('initial')
        threats = state.get('threats')
    if path is not None and args.figure:
        field = scenario.threats if threats is None else ThreatField.from_arrays(*threats)
        plot_plan(args.figure, field, scenario.box, np.asarray(path)[0],
                  np.asarray(path)[-1], initial_path=initial, path=path,
                  title=f'{scenario.name}: last live plan of {state["plans"]}')
        print(f'{state["plans"]} plans; figure of the last one: {args.figure}')
    elif exit_code == 0:
        print('no plan arrived', file=sys.stderr)
        exit_code = 1
    return exit_code


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``threat_planner_demo``."""
    parser = argparse.ArgumentParser(prog='threat_planner_demo', description=__doc__.split(
        '\n\n')[0])
    parser.add_argument('--scenario', type=Path, default=DEFAULT_SCENARIO)
    parser.add_argument('--params', type=Path, default=DEFAULT_PARAMS)
    parser.add_argument('--method', default='best', choices=('paper', 'improved', 'best'))
    parser.add_argument('--rate', type=float, default=1.0, help='threat updates [Hz]')
    parser.add_argument('--drift', type=float, default=1.0, help='threat motion [m/s]')
    parser.add_argument('--duration', type=float, help='stop after this many seconds')
    parser.add_argument('--figure', default='demo_out/last_plan.png')
    args = parser.parse_args(argv)
    if not args.scenario.exists():
        parser.exit(2, f'threat_planner_demo: error: {args.scenario}: no such file\n')
    return run(args)


if __name__ == '__main__':
    sys.exit(main())
