"""The planner node recording to a full disk (issue 14): it keeps planning and says why.

A small tmpfs is the disk (root mounts it; skipped with the reason elsewhere). Three
phases: ``record`` on a full disk at start-up (the node exits 1 with one "cannot start
recording" line), a run-time ``record`` change to a full disk (refused with the reason,
the node keeps planning), and the disk filling up while recording, in file and folder
mode (one ERROR line and a WARN ``plan_info``, planning continues, a clean exit, and what
was written before is readable).
"""

import signal

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
import pytest
from sensor_msgs.msg import PointCloud2

from node_harness import (cloud, domain_id, info, planner_command, REPO, RosClient,
                          start_process, stop_process, VOLATILE)
from test_recording_full_disk import fill, small_disk
from threat_planner.bag import read_messages
from threat_planner.core.scenario import load_scenario


DOMAIN = domain_id(41)
SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')
FAST = {'method': 'paper', 'start': SCENARIO.start.tolist(), 'goal': SCENARIO.goal.tolist(),
        'bounds': SCENARIO.box.lo.tolist() + SCENARIO.box.hi.tolist()}


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'full_disk_client')
    yield c
    c.close()


class Node:
    """A planner process in namespace `ns` and its plan_info stream."""

    def __init__(self, client, ns, params, log_path):
        self.client, self.ns, self.log_path = client, ns, log_path
        self.proc = start_process(planner_command(ns, params), DOMAIN, log_path)
        client.subscribe(f'{ns}/plan_info', DiagnosticArray)
        self.threats = client.publisher(f'{ns}/threats', PointCloud2)
        self.start = client.publisher(f'{ns}/start', PoseStamped, VOLATILE)
        client.wait_matched(self.threats, timeout=30.0)
        self.sec = 0

    def publish_picture(self):
        self.sec += 1
        self.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   stamp=Time(sec=self.sec)))
        return self.sec

    def wait_info(self, pred, timeout=30.0):
        return info(self.client.wait_for(f'{self.ns}/plan_info', lambda m: pred(info(m)),
                                         timeout))

    def plan_of(self, sec):
        stamp = str(sec * 1_000_000_000)
        return self.wait_info(lambda i: 'J' in i and i['input_stamp_ns'] == stamp)

    def log(self):
        return self.log_path.read_text(errors='replace')


def test_record_on_a_full_disk_at_start_up_exits_with_one_line(tmp_path):
    with small_disk(tmp_path) as disk:
        fill(disk)
        log = tmp_path / 'node.log'
        proc = start_process(planner_command('/fd_start', dict(FAST, record=str(disk / 'b'))),
                             DOMAIN, log)
        assert proc.wait(30) == 1
        text = log.read_text()
        lines = [line for line in text.splitlines() if 'cannot start recording' in line]
        assert len(lines) == 1 and 'No space left on device' in lines[0], text
        assert 'Traceback' not in text, text


def test_record_change_to_a_full_disk_is_refused_and_planning_continues(client, tmp_path):
    with small_disk(tmp_path) as disk:
        fill(disk)
        node = Node(client, '/fd_change', FAST, tmp_path / 'node.log')
        try:
            node.plan_of(node.publish_picture())
            for target in (disk / 'x.mcap', disk / 'bags'):
                result = client.set_parameters(f'{node.ns}/threat_planner',
                                               {'record': str(target)})[0]
                assert not result.successful
                assert 'cannot create recording' in result.reason
                assert 'No space left on device' in result.reason
            node.plan_of(node.publish_picture())
        finally:
            code = stop_process(node.proc, signal.SIGTERM)
        assert code == 0, node.log()
        assert 'Traceback' not in node.log(), node.log()


@pytest.mark.parametrize('name', ['run.mcap', 'bags'])
def test_disk_filling_up_while_recording_stops_recording_not_planning(client, tmp_path, name):
    with small_disk(tmp_path) as disk:
        ns = '/fd_fill_' + name.replace('.', '_')
        node = Node(client, ns, dict(FAST, record=str(disk / name)), tmp_path / 'node.log')
        try:
            warning = None
            for _ in range(200):
                node.plan_of(node.publish_picture())
                warns = [i for _, m in client.messages[f'{ns}/plan_info']
                         for i in [info(m)] if 'recording_error' in i]
                if warns:
                    warning = warns[0]
                    break
            assert warning is not None, 'the disk never filled: make it smaller'
            assert 'recording stopped' in warning['message']
            assert 'No space left on device' in warning['recording_error']
            # Planning goes on, and more plans do not bring the error back.
            for _ in range(3):
                node.plan_of(node.publish_picture())
        finally:
            code = stop_process(node.proc, signal.SIGTERM)
        text = node.log()
        assert code == 0, text
        assert 'Traceback' not in text, text
        assert sum('recording stopped' in line for line in text.splitlines()) == 1, text
        files = list(disk.rglob('*.mcap'))
        assert len(files) == 1
        back = list(read_messages(files[0], tolerant=True))
        assert any(m.topic == f'{ns}/threats' for m in back)
