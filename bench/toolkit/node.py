"""Planner node processes and the ROS client of the node suites.

The node suites start ``planner_node`` as a process of its own in a ROS domain of its own
(discovery limited to this host) through ``test/node_harness.py``, the harness the node
tests use; importing this module puts ``test/`` on ``sys.path`` for it and re-exports
what the suites take from it.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Iterator, Optional

from bench.toolkit.repo import ROOT

if str(ROOT / 'test') not in sys.path:
    sys.path.insert(0, str(ROOT / 'test'))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from node_harness import (cloud, domain_id, info, LATCHED, LATCHED_LOG,  # noqa: E402
                          planner_command, pose, PYTHON, RosClient, start_process,
                          stop_process, VOLATILE)
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402

from threat_planner.core.inputs.scenario import Scenario  # noqa: E402
from threat_planner.ros.conversions import ns_to_stamp, stamp_to_ns  # noqa: E402

__all__ = ['cloud', 'domain_id', 'info', 'jitter', 'LATCHED', 'LATCHED_LOG', 'log_stamp',
           'NodeProcess', 'ParameterProbe', 'planner_command', 'pose', 'PYTHON', 'RosClient',
           'ros_session', 'round_trip', 'scenario_params', 'STAMP0_NS', 'start_process',
           'stop_process', 'subscribe_answers', 'VOLATILE']


def log_stamp(log: Path, text: str) -> float | None:
    """Return the ROS log stamp [s since the epoch] of the first line holding `text`."""
    for line in log.read_text(errors='replace').splitlines():
        if text in line and line.startswith('[') and '] [' in line:
            try:
                return float(line.split('] [', 2)[1].split(']', 1)[0])
            except ValueError:
                continue
    return None


#: Stamp of the first counted input of a stream [ns]; later ones count up from it.
STAMP0_NS = 1_000 * 10**9


def scenario_params(scenario: Scenario, frame: bool = True, **extra) -> dict:
    """Node parameters for a scenario's bounds, start, goal (and frame), plus `extra`."""
    params = {'bounds': scenario.box.lo.tolist() + scenario.box.hi.tolist(),
              'start': scenario.start.tolist(), 'goal': scenario.goal.tolist()}
    if frame:
        params['frame_id'] = scenario.frame_id
    params.update(extra)
    return params


def jitter(positions: NDArray, rng: np.random.Generator) -> NDArray:
    """Return the positions each moved by a few centimetres, so that a picture is new [m]."""
    return positions + rng.normal(scale=0.05, size=positions.shape)


@contextmanager
def ros_session(offset: int, span: int, name: str, prefix: Optional[str] = None
                ) -> Iterator[tuple[RosClient, Optional[Path]]]:
    """Yield a client in a domain of its own and a temporary folder (with `prefix`)."""
    client = RosClient(domain_id(offset, span=span), name)
    try:
        if prefix is None:
            yield client, None
        else:
            with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
                yield client, Path(tmp)
    finally:
        client.close()


def subscribe_answers(client: RosClient, ns: str) -> None:
    """Subscribe to the ``path`` and ``plan_info`` of the node in `ns`."""
    client.subscribe(f'{ns}/path', PathMsg)
    client.subscribe(f'{ns}/plan_info', DiagnosticArray)


def round_trip(client: RosClient, ns: str, msg: PointCloud2, timeout: float,
               what: str = '') -> tuple[float, float, dict]:
    """Publish one picture to the node in `ns` and wait for its answers.

    ``plan_info`` carries the picture's stamp; the paths carry the plan's t0, which
    ``plan_info`` names (``t0_ns``), so the path is picked from what arrived by that.

    Returns
    -------
    path_ms, info_ms : float
        Time from ``publish()`` to the arrival of ``path`` and of ``plan_info`` [ms].
    values : dict
        The ``plan_info`` values; an ERROR one raises, naming `what` (default `ns`).
    """
    stamp = msg.header.stamp
    pub = client.publisher(f'{ns}/threats', PointCloud2)
    # The client stamps what it receives with time.monotonic(): the same clock here.
    t0 = time.monotonic()
    pub.publish(msg)
    values = info(client.wait_for(f'{ns}/plan_info', lambda m: m.header.stamp == stamp,
                                  timeout))
    t_info = time.monotonic()
    if values['level'] == 'ERROR':
        raise RuntimeError(f'{what or ns}: {values["message"]}')
    start_ns = int(values['t0_ns'])

    def answers(m) -> bool:
        return stamp_to_ns(m.header.stamp) == start_ns
    client.wait_for(f'{ns}/path', answers, timeout)
    t_path = next(t for t, m in list(client.messages[f'{ns}/path']) if answers(m))
    return 1e3 * (t_path - t0), 1e3 * (t_info - t0), values


class ParameterProbe:
    """Times ``get_parameters`` calls to a remote node.

    Parameters
    ----------
    client : RosClient
        The spinning client node the service client is created on.
    node_name : str
        Fully qualified name of the remote node.
    """

    def __init__(self, client: RosClient, node_name: str) -> None:
        self._params = AsyncParameterClient(client.node, node_name)

    def wait_ready(self, timeout: float = 30.0) -> bool:
        """Wait up to `timeout` [s] for the node's parameter services; whether they came."""
        return self._params.wait_for_services(timeout_sec=timeout)

    def get_ms(self, name: str = 'max_threats', timeout: float = 5.0) -> float:
        """Time one get of parameter `name` [ms]; ``inf`` if no answer within `timeout` [s]."""
        done = threading.Event()
        t0 = time.perf_counter()
        future = self._params.get_parameters([name])
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout) or future.result() is None:
            return float('inf')
        return 1e3 * (time.perf_counter() - t0)


class NodeProcess:
    """A planner node process with the client-side topics of its namespace.

    Parameters
    ----------
    client : RosClient
        Client in the node's domain.
    ns : str
        Namespace.
    params : dict
        Node parameters.
    log_path : Path
        Log file; run k of the process logs to ``<stem>_k.log`` beside it.
    """

    def __init__(self, client: RosClient, ns: str, params: dict, log_path: Path) -> None:
        self.client, self.ns, self.params, self.log_path = client, ns, params, log_path
        self.info_topic = f'{ns}/plan_info'
        client.subscribe(self.info_topic, DiagnosticArray)
        self.threats = client.publisher(f'{ns}/threats', PointCloud2, LATCHED)
        self.proc: Optional[subprocess.Popen] = None
        self.runs = 0

    def start(self) -> int:
        """Start (or restart) the process; return the plan_info count before it."""
        before = self.client.count(self.info_topic)
        log = self.log_path.with_name(f'{self.log_path.stem}_{self.runs}.log')
        self.proc = start_process(planner_command(self.ns, self.params), self.client.domain,
                                  log)
        self.runs += 1
        self.client.wait_matched(self.threats, timeout=30.0)
        return before

    def wait_answer(self, stamp_ns: int, after: int, timeout: float = 60.0) -> dict:
        """Wait for the plan_info answering the input stamped `stamp_ns` (after index `after`)."""
        return info(self.client.wait_for(
            self.info_topic, lambda m: int(info(m)['input_stamp_ns']) == stamp_ns,
            timeout, after=after))

    def answered(self, stamp_ns: int, after: int) -> bool:
        """Return whether an answer to `stamp_ns` came after index `after`."""
        return any(int(info(m)['input_stamp_ns']) == stamp_ns
                   for _, m in self.client.messages[self.info_topic][after:])

    def publish(self, positions: NDArray, intensities: NDArray, stamp_ns: int) -> float:
        """Publish a picture; return the monotonic time of the publish."""
        msg = cloud(positions, intensities, stamp=ns_to_stamp(stamp_ns))
        t = time.monotonic()
        self.threats.publish(msg)
        return t

    def kill(self) -> float:
        """SIGKILL the process; return the monotonic time of the kill."""
        t = time.monotonic()
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10.0)
        return t

    def stop(self) -> int:
        """SIGINT the process (SIGKILL after 10 s); return its exit code."""
        if self.proc is None or self.proc.poll() is not None:
            return self.proc.returncode if self.proc else 0
        self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(10.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(5.0)
