"""plan_path's bounded queue: with one request planning and 8 waiting, one more is refused.

The refused request is answered at once with an empty path, and the node logs the reason;
the 8 waiting are not dropped by it (the node is stopped before they are all planned).
"""

import time

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.srv import GetPlan
from sensor_msgs.msg import PointCloud2

from node_harness import (cloud, domain_id, planner_command, pose, REPO, RosClient,
                          start_process, stop_process)
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.ros.plan_service import QUEUE_BOUND

SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')


def test_the_request_beyond_the_bound_is_refused_with_an_empty_path(tmp_path):
    assert QUEUE_BOUND == 8
    domain = domain_id(191)
    log = tmp_path / 'node.log'
    # 'improved' sweeps 26 values of k for every entry/exit pair: at 1,000 segments each
    # request takes seconds (15 s here; the chain is compiled, 0.35 s at 40 segments) and
    # the topic plan is cut short by max_plan_time_s; requests have no limit.
    params = {'method': 'improved', 'n_points': 1000, 'max_plan_time_s': 1.0}
    proc = start_process(planner_command('/bound', params), domain, log)
    client = RosClient(domain, 'bound_client')
    try:
        client.subscribe('/bound/plan_info', DiagnosticArray)
        threats = client.publisher('/bound/threats', PointCloud2)
        client.wait_matched(threats, timeout=30.0)
        threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities))
        cli = client.node.create_client(GetPlan, '/bound/plan_path')
        assert cli.wait_for_service(timeout_sec=30.0)
        # The node holds the picture once it has published a plan_info for it (timed out).
        client.wait_for('/bound/plan_info', timeout=60.0)

        def call():
            return cli.call_async(GetPlan.Request(start=pose([0, 0, 50]),
                                                  goal=pose([100, 100, 50])))

        running = call()
        time.sleep(1.0)   # taken off the queue by the service's thread, now planning
        waiting = [call() for _ in range(QUEUE_BOUND)]
        refused = call()
        client.wait_until(refused.done, 20.0, 'the refused answer')
        assert refused.result().plan.poses == []
        assert refused.result().plan.header.frame_id == 'map'
        client.wait_until(lambda: 'request #10 refused: 8 requests already waiting'
                          in log.read_text(), 5.0, 'the logged reason')
        # Neither the one planning nor the 8 waiting were answered or dropped by it.
        assert not running.done() and not any(f.done() for f in waiting)
    finally:
        client.close()
        code = stop_process(proc)
    text = log.read_text(errors='replace')
    assert code == 0 and 'Traceback' not in text, text
