"""examples/feed_threats_and_plan.py, run as a user would against a real planner process."""

import subprocess

from node_harness import (domain_id, planner_command, PYTHON, REPO, ros_env, start_process,
                          stop_process)

EXAMPLE = REPO / 'examples' / 'feed_threats_and_plan.py'


def test_the_example_feeds_threats_and_gets_a_path(tmp_path):
    domain = domain_id(181)
    log = tmp_path / 'node.log'
    proc = start_process(planner_command('/uav7', {'method': 'paper'}), domain, log)
    try:
        run = subprocess.run([PYTHON, str(EXAMPLE), '--namespace', '/uav7', '--threats', '30'],
                             env=ros_env(domain), capture_output=True, text=True, timeout=120)
    finally:
        code = stop_process(proc)
    text = log.read_text(errors='replace')
    assert run.returncode == 0, (run.stdout, run.stderr, text)
    assert ' poses in map from (0.0, 0.0, 50.0) to (100.0, 100.0, 50.0)' in run.stdout
    # A path at all means the node holds the example's picture (else: 'no threat picture').
    assert 'plan_path request #' in text and code == 0 and 'Traceback' not in text, text
