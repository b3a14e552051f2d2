"""Shared parts of the planner node's tests (test_node*.py): a node process and messages.

PlannerProcess runs one ``python -m threat_planner.ros.node`` in a namespace of the
domain DOMAIN and subscribes and publishes its topics through a RosClient; the message
builders make hand-made, partly broken threat pictures from the scenario's.
"""

import signal
import threading

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Path as PathMsg
import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import MarkerArray
import yaml

from node_harness import (domain_id, info, LATCHED_LOG, planner_command, REPO, start_process,
                          stop_process, VOLATILE)
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.core.world.threats import ThreatField
from threat_planner.ros.conversions import stamp_to_ns, threats_from_pointcloud2
from threat_planner.ros.parameters import settings_from_parameters


DOMAIN = domain_id(1)
SCENARIO_FILE = REPO / 'test' / 'data' / 'uniform20_0.yaml'
SCENARIO = load_scenario(SCENARIO_FILE)
CONFIG_FILE = REPO / 'config' / 'planner.yaml'
FAST_MAX_THREATS = 50
# A flood publisher keeps every sample until delivered, so the node sees them all.
DEEP_LATCHED = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          history=HistoryPolicy.KEEP_LAST, depth=100)


def yaml_parameters():
    return yaml.safe_load(CONFIG_FILE.read_text())['threat_planner']['ros__parameters']


class PlannerProcess:
    """A planner node process and the client topics that go with its namespace."""

    def __init__(self, client, ns, params, log_path):
        self.client = client
        self.ns = ns
        self.log_path = log_path
        self.proc = start_process(planner_command(ns, params), DOMAIN, log_path)
        # Read as logs (LATCHED_LOG): at depth 1 the plan_info of a start's plan was lost
        # under load when the goal's plan followed it, and a test waiting for it by its
        # stamp timed out (test_node's pose_array_once, in a suite run beside busy processes).
        for name, msg_type in (('path', PathMsg), ('initial_path', PathMsg),
                               ('plan_info', DiagnosticArray), ('network', MarkerArray)):
            client.subscribe(self.topic(name), msg_type, LATCHED_LOG)
        self.threats = client.publisher(self.topic('threats'), PointCloud2)
        self.poses = client.publisher(self.topic('threat_poses'), PoseArray)
        self.start = client.publisher(self.topic('start'), PoseStamped, VOLATILE)
        self.goal = client.publisher(self.topic('goal_pose'), PoseStamped, VOLATILE)
        for pub in (self.threats, self.poses, self.start, self.goal):
            client.wait_matched(pub, timeout=30.0)

    def topic(self, name):
        return f'{self.ns}/{name}'

    @property
    def node_name(self):
        return f'{self.ns}/threat_planner'

    def infos(self):
        return [info(m) for _, m in list(self.client.messages[self.topic('plan_info')])]

    def last_seq(self):
        infos = self.infos()
        return int(infos[-1]['input_seq']) if infos else 0

    def wait_info(self, pred=lambda i: True, after_seq=None, timeout=30.0):
        """The first plan_info after input `after_seq` for which `pred` holds."""
        after_seq = self.last_seq() if after_seq is None else after_seq
        msg = self.client.wait_for(
            self.topic('plan_info'),
            lambda m: int(info(m)['input_seq']) > after_seq and pred(info(m)), timeout)
        return info(msg)

    def wait_plan(self, after_seq=None, timeout=60.0, pred=lambda i: True):
        """The next successful plan's info, path and initial path (matched by stamp: the
        paths carry the plan's t0, plan_info's ``t0_ns``)."""
        i = self.wait_info(lambda i: i['level'] != 'ERROR' and pred(i), after_seq, timeout)
        stamp = int(i['t0_ns'])
        path = self.client.wait_for(self.topic('path'),
                                    lambda m: stamp_to_ns(m.header.stamp) == stamp, 10.0)
        initial = self.client.wait_for(self.topic('initial_path'),
                                       lambda m: stamp_to_ns(m.header.stamp) == stamp, 10.0)
        return i, path, initial

    def alive(self):
        return self.proc.poll() is None

    def log(self):
        return self.log_path.read_text(errors='replace')

    def stop(self, sig=signal.SIGTERM):
        return stop_process(self.proc, sig)


def scenario_params(scenario=SCENARIO):
    box = scenario.box
    return {'bounds': box.lo.tolist() + box.hi.tolist(), 'start': scenario.start.tolist(),
            'goal': scenario.goal.tolist()}


def expected_plan(msg, start, goal, params):
    """What the library plans for the same (float32-rounded) cloud and parameters."""
    positions, intensities = threats_from_pointcloud2(msg, 'map')
    settings = settings_from_parameters(params)
    return plan(ThreatField.from_arrays(positions, intensities), start, goal, settings.box,
                settings.config)


def node_parameters(**changes):
    params = dict(yaml_parameters())
    params.update(changes)
    return params


def run_in_thread(fn, *args):
    """Run fn in a thread (numpy releases the GIL) and return a getter for its result."""
    box = {}
    thread = threading.Thread(target=lambda: box.update(result=fn(*args)))
    thread.start()

    def get():
        thread.join()
        return box['result']
    return get


def raw_cloud(positions, intensities, *, fields=None, point_step=16, frame='map', trim=0):
    """A hand-made float32 cloud with a chosen field list, point_step or cut-off data."""
    n = len(positions)
    data = np.zeros((n, point_step), np.uint8)
    values = np.column_stack([positions, intensities]).astype('<f4')
    width = min(point_step, 16)
    data[:, :width] = values.view(np.uint8).reshape(n, 16)[:, :width]
    msg = PointCloud2()
    msg.header.frame_id = frame
    msg.height, msg.width = 1, n
    msg.fields = fields if fields is not None else [
        PointField(name=name, offset=4 * k, datatype=PointField.FLOAT32, count=1)
        for k, name in enumerate(('x', 'y', 'z', 'intensity'))]
    msg.point_step = point_step
    msg.row_step = point_step * n
    msg.data = data.tobytes()[:len(data.tobytes()) - trim]
    msg.is_dense = True
    return msg


def _pos(**edit):
    p = SCENARIO.threats.positions.copy()
    for key, value in edit.items():
        row, col = int(key[1:].split('_')[0]), 'xyz'.index(key[-1])
        p[row, col] = value
    return p


def _inten(**edit):
    f = SCENARIO.threats.intensities.copy()
    for key, value in edit.items():
        f[int(key[1:])] = value
    return f


def _pose_array(positions, frame='map'):
    msg = PoseArray()
    msg.header.frame_id = frame
    msg.poses = [Pose() for _ in positions]
    for p, (x, y, z) in zip(msg.poses, np.asarray(positions).tolist()):
        p.position.x, p.position.y, p.position.z = x, y, z
    return msg
