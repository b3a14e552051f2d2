"""The planner node recording to a full disk (issue 14): it keeps planning and says why.

A small tmpfs is the disk (root mounts it; skipped with the reason elsewhere). Three
phases: ``record`` on a full disk at start-up (the node exits 1 with one "cannot start
recording" line), a run-time ``record`` change to a full disk (refused with the reason,
the node keeps planning), and the disk filling up while recording, in file and folder
mode (one ERROR line and a WARN ``plan_info``, planning continues, a clean exit, and what
was written before is readable).
"""

import signal

import pytest

from node_harness import (domain_id, info, planner_command, PlannerNode, REPO, RosClient,
                          start_process, stop_process)
from test_recording_full_disk import fill, small_disk
from threat_planner.bag import read_messages
from threat_planner.core.inputs.scenario import load_scenario


DOMAIN = domain_id(41)
SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')
FAST = {'method': 'paper', 'start': SCENARIO.start.tolist(), 'goal': SCENARIO.goal.tolist(),
        'bounds': SCENARIO.box.lo.tolist() + SCENARIO.box.hi.tolist()}


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'full_disk_client')
    yield c
    c.close()


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
        node = PlannerNode(client, DOMAIN, '/fd_change', FAST, tmp_path / 'node.log', SCENARIO)
        try:
            node.plan_of(node.picture())
            for target in (disk / 'x.mcap', disk / 'bags'):
                result = client.set_parameters(f'{node.ns}/threat_planner',
                                               {'record': str(target)})[0]
                assert not result.successful
                assert 'cannot create recording' in result.reason
                assert 'No space left on device' in result.reason
            node.plan_of(node.picture())
        finally:
            code = stop_process(node.proc, signal.SIGTERM)
        assert code == 0, node.log()
        assert 'Traceback' not in node.log(), node.log()


@pytest.mark.parametrize('name', ['run.mcap', 'bags'])
def test_disk_filling_up_while_recording_stops_recording_not_planning(client, tmp_path, name):
    with small_disk(tmp_path) as disk:
        ns = '/fd_fill_' + name.replace('.', '_')
        node = PlannerNode(client, DOMAIN, ns, dict(FAST, record=str(disk / name)),
                           tmp_path / 'node.log', SCENARIO)
        try:
            warning = None
            for _ in range(200):
                node.plan_of(node.picture())
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
                node.plan_of(node.picture())
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
