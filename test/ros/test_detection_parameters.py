"""The detection model's node parameters (issue 43): declared from the settings, checked.

cost_model, max_detection, scan_period_s, p_fa, swerling and rcs are parameters with the
descriptors of their settings; a bad value is refused with the reason, in-process
(settings_from_parameters) and by a running node, which keeps its plan and does not
replan; cost_model 'detection' needs method 'best'.
"""

import time

from rcl_interfaces.msg import ParameterType
from rclpy.parameter_client import AsyncParameterClient
import pytest

from node_fixtures import DOMAIN, PlannerProcess, SCENARIO
from node_harness import cloud, RosClient
from threat_planner.core.inputs.settings import NODE_SETTINGS
from threat_planner.errors import InputError
from threat_planner.ros.parameters import (descriptor, PARAMETER_DEFAULTS,
                                           PLANNING_PARAMETERS, settings_from_parameters)

DETECTION = ('cost_model', 'max_detection', 'scan_period_s', 'p_fa', 'swerling', 'rcs')
#: Bad values and the reason each is refused with.
REFUSED = {
    'rcs': ('ellipsoid 1 2', 'rcs: ellipsoid takes 3 values, got 2'),
    'p_fa': (0.0, 'p_fa: must satisfy 0 < p_fa < 1, got 0.0'),
    'scan_period_s': (0.0, 'scan_period_s: must be finite and > 0 and <= 3600, got 0.0'),
    'max_detection': (0.0, 'max_detection: must be finite and > 0 and <= 1, got 0.0'),
    'cost_model': ('risk', 'cost_model: must be one of paper, detection'),
}


# ------------------------------------------------------------ without a node


def test_every_detection_setting_is_a_parameter_that_can_change_the_plan():
    for name in DETECTION:
        assert PARAMETER_DEFAULTS[name] == NODE_SETTINGS[name].default, name
        assert name in PLANNING_PARAMETERS, name


def test_descriptors_carry_the_settings_help_rule_and_range():
    for name in DETECTION:
        s, d = NODE_SETTINGS[name], descriptor(name)
        assert (d.description, d.additional_constraints) == (s.doc, s.rule), name
    assert descriptor('swerling').type == ParameterType.PARAMETER_INTEGER
    r = descriptor('swerling').integer_range[0]
    assert (r.from_value, r.to_value) == (0, 1)
    assert descriptor('swerling').additional_constraints == 'must be 0 or 1'
    assert descriptor('rcs').type == ParameterType.PARAMETER_STRING
    assert descriptor('rcs').additional_constraints == ("must be 'constant S' or "
                                                        "'ellipsoid A B C'")
    f = descriptor('scan_period_s').floating_point_range[0]
    assert (f.from_value, f.to_value) == (0.0, 3600.0)
    assert descriptor('p_fa').type == ParameterType.PARAMETER_DOUBLE


@pytest.mark.parametrize('name', sorted({**REFUSED, 'swerling': None}))
def test_settings_refuse_a_bad_detection_value_with_the_reason(name):
    value, reason = REFUSED.get(name, (2, 'swerling: must be 0 or 1, got 2'))
    with pytest.raises(InputError) as err:
        settings_from_parameters({**PARAMETER_DEFAULTS, name: value})
    assert reason in str(err.value)


def test_cost_detection_is_accepted_with_method_best_and_refused_with_paper():
    s = settings_from_parameters({**PARAMETER_DEFAULTS, 'cost_model': 'detection',
                                  'rcs': 'ellipsoid 3 1 0.5', 'swerling': 0})
    assert (s.config.cost_model, s.config.rcs, s.config.swerling) == (
        'detection', 'ellipsoid 3 1 0.5', 0)
    with pytest.raises(InputError, match='cost_model: detection needs method best'):
        settings_from_parameters({**PARAMETER_DEFAULTS, 'cost_model': 'detection',
                                  'method': 'paper'})


# ------------------------------------------------------------- a running node


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'test_detection_parameters_client')
    yield c
    c.close()


@pytest.fixture(scope='module')
def paper_node(client, tmp_path_factory):
    """Method 'paper' (fast), the default start and goal, config/planner.yaml's values,
    planning the scenario's threats."""
    node = PlannerProcess(client, '/detection_params', {'method': 'paper'},
                          tmp_path_factory.mktemp('detection') / 'node.log')
    node.threats.publish(cloud(SCENARIO.threats.positions, SCENARIO.threats.intensities))
    node.wait_plan(after_seq=0)
    yield node
    assert node.stop() == 0, node.log()


def test_the_node_declares_them_with_their_defaults_and_descriptors(paper_node):
    params = AsyncParameterClient(paper_node.client.node, paper_node.node_name)
    assert params.wait_for_services(timeout_sec=10.0)
    values = params.get_parameters(list(DETECTION))
    described = params.describe_parameters(list(DETECTION))
    paper_node.client.wait_until(lambda: values.done() and described.done(), 10.0,
                                 'get and describe parameters')
    got = {name: getattr(v, {ParameterType.PARAMETER_STRING: 'string_value',
                             ParameterType.PARAMETER_DOUBLE: 'double_value',
                             ParameterType.PARAMETER_INTEGER: 'integer_value'}[v.type])
           for name, v in zip(DETECTION, values.result().values)}
    assert got == {name: PARAMETER_DEFAULTS[name] for name in DETECTION}
    for name, d in zip(DETECTION, described.result().descriptors):
        assert (d.name, d.description, d.additional_constraints) == (
            name, NODE_SETTINGS[name].doc, NODE_SETTINGS[name].rule)


def test_the_node_refuses_a_bad_value_with_the_reason_and_keeps_its_plan(paper_node):
    client = paper_node.client
    count = client.count(paper_node.topic('plan_info'))
    for name, (value, reason) in REFUSED.items():
        result = client.set_parameters(paper_node.node_name, {name: value})[0]
        assert not result.successful, name
        assert reason in result.reason, (name, result.reason)
    # swerling 2 is outside the descriptor's integer range: rclpy refuses it.
    result = client.set_parameters(paper_node.node_name, {'swerling': 2})[0]
    assert not result.successful, 'swerling 2'
    assert 'swerling' in result.reason and 'out of range' in result.reason, result.reason
    # A detection cost on this method 'paper' node: refused, naming the rule.
    result = client.set_parameters(paper_node.node_name, {'cost_model': 'detection'})[0]
    assert not result.successful
    assert 'cost_model: detection needs method best' in result.reason, result.reason
    time.sleep(0.3)
    assert client.count(paper_node.topic('plan_info')) == count, 'a refused change replanned'
    assert paper_node.alive()


def test_a_good_value_is_taken_and_replans(paper_node):
    seq = paper_node.last_seq()
    results = paper_node.client.set_parameters(
        paper_node.node_name, {'swerling': 0, 'rcs': 'ellipsoid 3 1 0.5', 'p_fa': 1.0e-4,
                               'scan_period_s': 2.0})
    assert all(r.successful for r in results), [r.reason for r in results]
    info, _, _ = paper_node.wait_plan(after_seq=seq)
    assert info['input_source'] == 'parameters'
