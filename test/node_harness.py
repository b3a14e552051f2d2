"""Helpers for tests and benchmarks that talk to a planner node in another process.

The calling process gets its own rclpy context (never the default one, so pytest keeps its
signal handling) whose executor spins in a background thread; received messages are kept
per topic and waited for with :meth:`RosClient.wait_for`.
"""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time
from typing import Callable, Optional, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from threat_planner.ros.conversions import plan_info_values, pointcloud2_from_threats
from threat_planner.ros.discovery import PROFILE, PROFILE_VARIABLES

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable

LATCHED = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=1)
#: A latched topic read as a log: the last message on joining, then every one after it
#: (depth 1 drops one of two messages that arrive before this process takes the first:
#: a WARN plan_info published just before the next plan's was lost under load).
LATCHED_LOG = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         history=HistoryPolicy.KEEP_LAST, depth=100)
VOLATILE = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE,
                      history=HistoryPolicy.KEEP_LAST, depth=10)
LEVEL_NAMES = {DiagnosticStatus.OK: 'OK', DiagnosticStatus.WARN: 'WARN',
               DiagnosticStatus.ERROR: 'ERROR'}


#: Fast DDS computes its ports from the domain id; above 232 they pass 65535 and the
#: participant cannot be created (the process then dies without a word).
MAX_DOMAIN_ID = 232


def domain_id(offset: int, span: int = 40) -> int:
    """Return a ROS domain id for this process: `offset` + pid modulo `span`.

    Raises ValueError for an offset whose range reaches past MAX_DOMAIN_ID.
    """
    if offset + span - 1 > MAX_DOMAIN_ID:
        raise ValueError(f'domain offset {offset} + span {span} passes {MAX_DOMAIN_ID}')
    domain = offset + os.getpid() % span
    # Under pytest-xdist each worker takes the domains of its own residue, so files that
    # run at the same time in two workers never share one (within a worker they take turns).
    workers = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    if workers > 1 and worker.startswith('gw'):
        domain += (int(worker[2:]) - domain) % workers
        if domain > MAX_DOMAIN_ID:
            domain -= workers
    return domain


def set_discovery_env(env) -> None:
    """Discovery on this host only, with the package's fast-announcing profile.

    The profile is set for the test's own participants too, which run no executable of the
    package (:mod:`threat_planner.ros.discovery`); unless a profile is set already.
    """
    # Only this machine: DDS discovery must not leave the host.
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    for name in PROFILE_VARIABLES:
        env.setdefault(name, str(PROFILE))


def ros_env(domain: int, extra_pythonpath: Sequence[str] = ()) -> dict[str, str]:
    """Environment for a node process: the domain, localhost discovery, unbuffered output."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    set_discovery_env(env)
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_LOGGING_BUFFERED_STREAM'] = '0'
    paths = list(extra_pythonpath) + [str(REPO)]
    if env.get('PYTHONPATH'):
        paths.append(env['PYTHONPATH'])
    env['PYTHONPATH'] = os.pathsep.join(paths)
    return env


def start_process(cmd: Sequence[str], domain: int, log_path: Path,
                  extra_pythonpath: Sequence[str] = ()) -> subprocess.Popen:
    """Start a ROS process with its stdout and stderr in `log_path`."""
    log = open(log_path, 'wb')
    try:
        return subprocess.Popen(list(cmd), cwd=str(REPO), stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL,
                                env=ros_env(domain, extra_pythonpath))
    finally:
        log.close()


def planner_command(namespace: str = '', params: Optional[dict] = None,
                    params_file: Optional[Path] = REPO / 'config' / 'planner.yaml',
                    executable: Optional[Sequence[str]] = None) -> list[str]:
    """Command line of a planner node with a namespace, a params file and overrides."""
    cmd = list(executable or [PYTHON, '-m', 'threat_planner.ros.entry', 'planner_node'])
    cmd.append('--ros-args')
    if namespace:
        cmd += ['-r', f'__ns:={namespace}']
    if params_file is not None:
        cmd += ['--params-file', str(params_file)]
    for name, value in (params or {}).items():
        cmd += ['-p', f'{name}:={_param_text(value)}']
    return cmd


def _param_text(value: object) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ','.join(_param_text(v) for v in value) + ']'
    if isinstance(value, str):
        return value if value else "''"
    return repr(value)


def stop_process(proc: subprocess.Popen, sig: int = signal.SIGTERM,
                 timeout: float = 10.0) -> int:
    """Signal a process and wait for it; kill it if it does not end in time."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
    return proc.returncode


def pose(xyz: Sequence[float], frame_id: str = 'map', stamp: Optional[Time] = None
         ) -> PoseStamped:
    """Build a PoseStamped at `xyz`."""
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
    msg.pose.orientation.w = 1.0
    return msg


def cloud(positions, intensities, frame_id: str = 'map', stamp: Optional[Time] = None):
    """Build a PointCloud2 of the threats (float32 x, y, z, intensity)."""
    return pointcloud2_from_threats(positions, intensities, frame_id, stamp or Time())


def info(msg: DiagnosticArray) -> dict[str, str]:
    """plan_info as a dict, with 'level' and 'message' added."""
    values = plan_info_values(msg)
    values['level'] = LEVEL_NAMES.get(msg.status[0].level, str(msg.status[0].level))
    values['message'] = msg.status[0].message
    return values


class RosClient:
    """A node in its own context, spun in a background thread.

    Parameters
    ----------
    domain : int
        ROS domain id.
    name : str
        Node name.

    """

    def __init__(self, domain: int, name: str = 'test_client') -> None:
        # Read when the first participant of this process is created.
        set_discovery_env(os.environ)
        self.domain = domain
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._cond = threading.Condition()
        self.messages: dict[str, list[tuple[float, object]]] = {}
        self._publishers: dict[tuple[str, type], object] = {}
        self._subs: dict[str, object] = {}
        self._param_clients: dict[str, AsyncParameterClient] = {}
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # noqa: B902 - shutting down the context ends spin() this way
            pass

    def close(self) -> None:
        """Shut the context down and stop the spin thread."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(5.0)

    # -- publishing ------------------------------------------------------------------

    def publisher(self, topic: str, msg_type: type, qos: QoSProfile = LATCHED):
        """Return a publisher, created on first use."""
        key = (topic, msg_type, id(qos))
        if key not in self._publishers:
            self._publishers[key] = self.node.create_publisher(msg_type, topic, qos)
        return self._publishers[key]

    def wait_matched(self, publisher, count: int = 1, timeout: float = 10.0) -> None:
        """Wait until `publisher` has `count` subscriptions."""
        self.wait_until(lambda: publisher.get_subscription_count() >= count, timeout,
                        f'{publisher.topic_name} subscriber')

    # -- subscribing -----------------------------------------------------------------

    def subscribe(self, topic: str, msg_type: type, qos: QoSProfile = LATCHED) -> None:
        """Keep every message of `topic` (with its receive time) in ``messages[topic]``."""
        if topic in self._subs:
            return
        self.messages.setdefault(topic, [])

        def on_msg(msg, topic=topic) -> None:
            with self._cond:
                self.messages[topic].append((time.monotonic(), msg))
                self._cond.notify_all()
        self._subs[topic] = self.node.create_subscription(msg_type, topic, on_msg, qos)

    def unsubscribe(self, topic: str) -> None:
        """Drop a subscription and what it received."""
        sub = self._subs.pop(topic, None)
        if sub is not None:
            self.node.destroy_subscription(sub)
        with self._cond:
            self.messages.pop(topic, None)

    def count(self, topic: str) -> int:
        """Messages received on `topic` so far."""
        with self._cond:
            return len(self.messages.get(topic, []))

    def last(self, topic: str):
        """Return the latest message on `topic`, or None."""
        with self._cond:
            msgs = self.messages.get(topic, [])
            return msgs[-1][1] if msgs else None

    def wait_for(self, topic: str, predicate: Callable[[object], bool] = lambda m: True,
                 timeout: float = 20.0, after: int = 0):
        """Wait for a message on `topic` (from index `after` on) that satisfies `predicate`."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for _, msg in self.messages.get(topic, [])[after:]:
                    if predicate(msg):
                        return msg
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f'no matching message on {topic} within {timeout} s '
                                       f'({len(self.messages.get(topic, []))} received)')
                self._cond.wait(min(left, 0.1))

    def wait_future(self, future, timeout: float, what: str):
        """Wait for an rclpy future and return its result, woken the moment it is done.

        Polling ``future.done`` (as :meth:`wait_until` does) adds up to one poll period to
        every wait: GetPlan round trips measured that way came out in steps of 20 ms.
        """
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            raise TimeoutError(f'timed out after {timeout} s waiting for {what}')
        return future.result()

    def wait_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        """Poll `condition` until true."""
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise TimeoutError(f'timed out after {timeout} s waiting for {what}')
            time.sleep(0.02)

    # -- parameters ------------------------------------------------------------------

    def set_parameters(self, node_name: str, params: dict, timeout: float = 10.0,
                       atomically: bool = False):
        """Set parameters of a remote node; return the list of SetParametersResult."""
        client = self._param_clients.get(node_name)
        if client is None:
            client = AsyncParameterClient(self.node, node_name)
            self._param_clients[node_name] = client
        if not client.wait_for_services(timeout_sec=timeout):
            raise TimeoutError(f'parameter services of {node_name} not available')
        plist = [Parameter(name, value=value) for name, value in params.items()]
        if atomically:
            future = client.set_parameters_atomically(plist)
        else:
            future = client.set_parameters(plist)
        self.wait_until(future.done, timeout, f'set_parameters on {node_name}')
        response = future.result()
        return [response.result] if atomically else list(response.results)


class PlannerNode:
    """A planner process in namespace `ns`, with this process's publishers for it.

    `plan_info` and `path` are subscribed; `threats`, `threat_poses` and `start` have
    publishers. Input stamps count up from 1 s, so each answer can be found by its stamp.
    """

    def __init__(self, client: 'RosClient', domain: int, ns: str, params: dict,
                 log_path: Path, scenario) -> None:
        from geometry_msgs.msg import PoseArray
        from nav_msgs.msg import Path as PathMsg
        from sensor_msgs.msg import PointCloud2
        self.client, self.ns, self.log_path, self.scenario = client, ns, log_path, scenario
        self.proc = start_process(planner_command(ns, params), domain, log_path)
        client.subscribe(f'{ns}/plan_info', DiagnosticArray, LATCHED_LOG)
        client.subscribe(f'{ns}/path', PathMsg)
        self.threats = client.publisher(f'{ns}/threats', PointCloud2)
        self.poses = client.publisher(f'{ns}/threat_poses', PoseArray)
        self.start = client.publisher(f'{ns}/start', PoseStamped, VOLATILE)
        for pub in (self.threats, self.poses, self.start):
            client.wait_matched(pub, timeout=30.0)
        self.sec = 0

    @property
    def name(self) -> str:
        """Fully qualified node name."""
        return f'{self.ns}/threat_planner'

    def stamp(self) -> Time:
        """The next input stamp."""
        self.sec += 1
        return Time(sec=self.sec)

    def picture(self) -> int:
        """Publish the scenario's threat picture; return its stamp [s]."""
        stamp = self.stamp()
        self.threats.publish(cloud(self.scenario.threats.positions,
                                   self.scenario.threats.intensities, stamp=stamp))
        return stamp.sec

    def answer(self, sec: int, timeout: float = 60.0) -> dict:
        """The plan_info that answers the input stamped `sec`."""
        stamp = str(sec * 1_000_000_000)
        return info(self.client.wait_for(
            f'{self.ns}/plan_info', lambda m: info(m)['input_stamp_ns'] == stamp, timeout))

    def plan_of(self, sec: int, timeout: float = 30.0) -> dict:
        """The plan_info of the plan (not an error) for the input stamped `sec`."""
        stamp = str(sec * 1_000_000_000)
        return info(self.client.wait_for(
            f'{self.ns}/plan_info',
            lambda m: 'J' in info(m) and info(m)['input_stamp_ns'] == stamp, timeout))

    def log(self) -> str:
        """The node's log so far."""
        return self.log_path.read_text(errors='replace')
