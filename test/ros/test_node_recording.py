"""Tests of the planner node's recording and of its exit on bad start-up parameters.

Each node runs as its own process in a namespace of the domain shared with test_node.py
(see node_fixtures.py); this process talks to them through its own rclpy context.
"""

import math
import signal

from builtin_interfaces.msg import Time
import pytest

from node_fixtures import _inten, _pos, DOMAIN, PlannerProcess, SCENARIO
from node_harness import cloud, planner_command, pose, RosClient, start_process
from threat_planner.bag import read_messages
from threat_planner.ros.parameters import PARAMETER_DEFAULTS


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'test_node_recording_client')
    yield c
    c.close()


def test_recording_holds_inputs_and_outputs(client, tmp_path):
    target = tmp_path / 'run.mcap'
    node = PlannerProcess(client, '/rec', {'method': 'paper', 'record': str(target)},
                          tmp_path / 'node.log')
    try:
        node.start.publish(pose(SCENARIO.start, stamp=Time(sec=1)))
        node.goal.publish(pose(SCENARIO.goal, stamp=Time(sec=2)))
        node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   stamp=Time(sec=3)))
        node.wait_plan(after_seq=0, pred=lambda i: i['inputs_received'] == '3')
        assert client.set_parameters(node.node_name, {'w': 0.7})[0].successful
        node.wait_plan(after_seq=0, pred=lambda i: i['input_source'] == 'parameters')
        node.threats.publish(cloud(_pos(p0_x=math.nan), _inten(), stamp=Time(sec=4)))
        node.wait_info(lambda i: i['level'] == 'ERROR')
        # Switch to folder mode at run time: the file is finished, a bag is started.
        bags = tmp_path / 'bags'
        assert client.set_parameters(node.node_name, {'record': str(bags)})[0].successful
        seq = node.last_seq()
        node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities,
                                   stamp=Time(sec=5)))
        node.wait_plan(after_seq=seq)
    finally:
        code = node.stop(signal.SIGTERM)
    assert code == 0, node.log()
    assert 'closed recording' in node.log()

    recorded = list(read_messages(target))  # strict: the file was finished
    topics = {m.topic for m in recorded}
    assert topics >= {'/rec/threats', '/rec/start', '/rec/goal_pose', '/parameter_events',
                      '/rec/initial_path', '/rec/path', '/rec/network', '/rec/plan_info'}
    by_topic = {t: [m for m in recorded if m.topic == t] for t in topics}
    assert len(by_topic['/rec/threats']) == 2  # the good and the bad picture
    events = by_topic['/parameter_events']
    assert {p.name for p in events[0].msg.new_parameters} == set(PARAMETER_DEFAULTS)
    assert [p.name for p in events[-1].msg.changed_parameters] == ['w']
    # Outputs are logged when published, after the input they answer was received.
    first_in = min(m.log_time_ns for m in by_topic['/rec/threats'])
    assert all(m.log_time_ns >= first_in for m in by_topic['/rec/path'])
    assert any(m.msg.status[0].level == 2 for m in by_topic['/rec/plan_info'])

    bag_dirs = [d for d in bags.iterdir() if d.is_dir()]
    assert len(bag_dirs) == 1 and (bag_dirs[0] / 'metadata.yaml').is_file()
    in_bag = {m.topic for m in read_messages(bag_dirs[0])}
    assert {'/rec/threats', '/rec/path', '/rec/plan_info', '/parameter_events'} <= in_bag


def test_bad_start_up_parameters_exit_with_reason(tmp_path):
    log = tmp_path / 'node.log'
    proc = start_process(planner_command('/bad', {'w': 0.0}), DOMAIN, log)
    assert proc.wait(30) == 1
    assert 'cannot start: w: must satisfy 0 < w < 1' in log.read_text()
    proc = start_process(planner_command('/bad', {'record': '/proc/forbidden/x.mcap'}),
                         DOMAIN, log)
    assert proc.wait(30) == 1
    assert ('cannot start recording: /proc/forbidden/x.mcap: cannot create recording'
            in log.read_text())
