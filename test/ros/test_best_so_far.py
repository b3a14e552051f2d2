"""A plan stopped by max_plan_time_s publishes its best path so far (issue 14 item 2).

* the core hands the network route over (``plan(on_initial=...)``) as soon as the search
  has it, with its exact cost, and for 'paper' it is the result's initial path;
* a node whose plan times out publishes that route on ``path`` and ``initial_path`` and a
  WARN ``plan_info`` saying "timed out", with the route's exact J.
"""

import signal

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2

from node_harness import (cloud, domain_id, info, planner_command, REPO, RosClient,
                          start_process, stop_process)
from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan
from threat_planner.ros.conversions import path_from_msg, stamp_to_ns

SCENARIO = load_scenario(REPO / 'test' / 'data' / 'uniform20_0.yaml')


def exact(points, w):
    return path_cost(points, SCENARIO.threats.positions, SCENARIO.threats.intensities, w)


@pytest.mark.parametrize('method', ['paper', 'improved', 'best'])
def test_the_core_hands_over_the_route_before_it_optimises(method):
    got = []
    cfg = PlannerConfig(method=method, w=0.3)
    result = plan(SCENARIO.threats, SCENARIO.start, SCENARIO.goal, SCENARIO.box, cfg,
                  on_initial=lambda points, cost: got.append((points.copy(), cost)))
    assert len(got) == 1
    points, cost = got[0]
    assert (points[0] == SCENARIO.start).all() and (points[-1] == SCENARIO.goal).all()
    # Exact: the closed form (compiled or numpy; they differ only in summation order).
    ref = exact(points, 0.3)
    assert cost.J_L == ref.J_L
    assert cost.J == pytest.approx(ref.J, rel=1e-12)
    assert cost.J_R == pytest.approx(ref.J_R, rel=1e-12)
    # A route through the network nodes: every interior point is a node.
    nodes = result.network.nodes
    for p in points[1:-1]:
        assert np.min(np.linalg.norm(nodes - p, axis=1)) == 0.0
    if method == 'paper':
        assert (points == result.initial_path).all()
    # The optimised path is no worse than the route handed over early.
    assert result.cost.J <= cost.J * (1 + 1e-9)


def test_no_hook_plans_exactly_as_before():
    cfg = PlannerConfig(method='best')
    a = plan(SCENARIO.threats, SCENARIO.start, SCENARIO.goal, SCENARIO.box, cfg)
    b = plan(SCENARIO.threats, SCENARIO.start, SCENARIO.goal, SCENARIO.box, cfg,
             on_initial=lambda points, cost: None)
    assert (a.path == b.path).all() and a.cost == b.cost


def test_a_timed_out_node_plan_publishes_the_best_path_so_far(tmp_path):
    domain = domain_id(141)
    # 'best' at 10,000 points takes many seconds; the search is done in milliseconds.
    params = {'method': 'best', 'n_points': 10000, 'max_plan_time_s': 0.5, 'w': 0.5,
              'start': SCENARIO.start.tolist(), 'goal': SCENARIO.goal.tolist(),
              'bounds': SCENARIO.box.lo.tolist() + SCENARIO.box.hi.tolist()}
    log = tmp_path / 'node.log'
    proc = start_process(planner_command('/late', params), domain, log)
    client = RosClient(domain, 'best_so_far_client')
    try:
        client.subscribe('/late/plan_info', DiagnosticArray)
        client.subscribe('/late/path', PathMsg)
        client.subscribe('/late/initial_path', PathMsg)
        threats = client.publisher('/late/threats', PointCloud2)
        client.wait_matched(threats, timeout=30.0)
        msg = cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities)
        msg.header.stamp.sec = 7
        threats.publish(msg)
        i = info(client.wait_for('/late/plan_info',
                                 lambda m: info(m)['input_stamp_ns'] == str(7 * 10**9),
                                 timeout=60.0))
        assert i['level'] == 'WARN' and 'timed out after' in i['message'], i['message']
        assert i['timed_out'] == 'True' and i['best_so_far'] == 'initial', i
        t0 = int(i['t0_ns'])   # the paths carry the plan's t0, not the input's stamp
        path = client.wait_for('/late/path', lambda m: stamp_to_ns(m.header.stamp) == t0)
        initial = client.wait_for('/late/initial_path',
                                  lambda m: stamp_to_ns(m.header.stamp) == t0)
        points = path_from_msg(path)
        assert (points == path_from_msg(initial)).all()
        assert len(points) == int(i['path_points']) >= 2
        assert np.allclose(points[0], SCENARIO.start) and np.allclose(points[-1], SCENARIO.goal)
        # The J reported is the exact J of the path published through the threats the
        # node holds (the cloud's float32 fields).
        f32 = [a.astype(np.float32).astype(float)
               for a in (SCENARIO.threats.positions, SCENARIO.threats.intensities)]
        assert float(i['J']) == pytest.approx(path_cost(points, *f32, 0.5).J, rel=1e-9)
    finally:
        client.close()
        code = stop_process(proc, signal.SIGTERM)
    text = log.read_text(errors='replace')
    assert code == 0 and 'Traceback' not in text, text
