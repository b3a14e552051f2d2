"""plan_info reports every plan's detection (issue 43): P_detect, H, the cost, the top shares.

The keys reach a recording unchanged: ``plan --record`` writes the node's plan_info.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from builtin_interfaces.msg import Time

from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.ros.conversions import plan_info_values
from threat_planner.ros.plan_info import detection_top, input_values, plan_done_info

DATA = Path(__file__).resolve().parents[1] / 'data'


@pytest.fixture(scope='module')
def scenario():
    return load_scenario(DATA / 'uniform20_0.yaml')


@pytest.fixture(scope='module')
def result(scenario):
    return plan(scenario.threats, scenario.start, scenario.goal, scenario.box,
                PlannerConfig(n_points=20))


def _info(result, n_threats):
    stamp = Time(sec=1, nanosec=0)
    values = input_values(1, '/threats', stamp, 'map', 1, 0, 0, 1)
    msg = plan_done_info(values, result, n_threats, stamp, 0.0, 1.0, 0.0)
    return plan_info_values(msg)


def test_detection_top_names_the_three_largest_shares_largest_first():
    assert detection_top([1.0, 5.0, 3.0, 1.0]) == '1:0.5,2:0.3,0:0.1'
    assert detection_top([2.0, 2.0]) == '0:0.5,1:0.5'   # fewer than 3 threats: all
    assert detection_top([0.0, 0.0]) == ''              # H = 0: no shares
    assert detection_top([]) == ''


def test_a_paper_plan_reports_its_detection_exactly_in_plan_info(result, scenario):
    values = _info(result, len(scenario.threats))
    report = result.detection
    assert values['cost_model'] == 'paper'
    # Floats are written with repr: they read back bit for bit.
    assert float(values['P_detect']) == report.p_detect
    assert float(values['H']) == report.hazard
    assert 0.0 < report.p_detect < 1.0
    top = [item.split(':') for item in values['detection_top'].split(',')]
    assert len(top) == 3
    idx = [int(i) for i, _ in top]
    shares = [float(v) for _, v in top]
    per = np.asarray(report.per_threat)
    assert idx == list(np.argsort(-per, kind='stable')[:3])
    np.testing.assert_allclose(shares, per[idx] / report.hazard, rtol=1e-3)
    assert shares == sorted(shares, reverse=True) and sum(shares) <= 1.0 + 1e-3
    # A paper plan has no detection objective or bound to report.
    assert 'detection_status' not in values and 'detection_objective' not in values


def test_a_detection_plan_reports_its_objective_and_its_bound_status(result, scenario):
    bounded = replace(result, cost_model='detection', objective=0.75,
                      detection_status='unmet: no path within the limits has P_detect <= 1e-09')
    values = _info(bounded, len(scenario.threats))
    assert values['cost_model'] == 'detection'
    assert float(values['detection_objective']) == 0.75
    assert values['detection_status'] == ('unmet: no path within the limits has '
                                          'P_detect <= 1e-09')
    assert float(values['P_detect']) == result.detection.p_detect


def test_a_recorded_plan_carries_the_detection_keys_into_the_bag(tmp_path, scenario):
    from threat_planner.ros.recording.bagfile import load_bag
    from threat_planner.ros.recording.record import record_plan
    cfg = PlannerConfig(n_points=20)
    result, path = record_plan(scenario, cfg, tmp_path / 'plan.mcap')
    plans = load_bag(path).plans
    assert len(plans) == 1
    values = plans[0].values
    assert values['cost_model'] == 'paper'
    assert float(values['P_detect']) == result.detection.p_detect
    assert float(values['H']) == result.detection.hazard
    assert values['detection_top'].count(':') == 3
