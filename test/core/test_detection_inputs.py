"""The detection model's inputs (issue 43): the scenario's ``detection`` block and the settings.

A scenario's block gives the settings cost_model, max_detection, speed_mps, scan_period_s,
p_fa, swerling and rcs; a bad value is one line naming the key as the file wrote it; the
block survives a save; cost_model 'detection' needs method 'best'.
"""

from pathlib import Path

import pytest
import yaml

from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import (load_scenario, save_scenario, Scenario,
                                                 scenario_from_dict)
from threat_planner.core.inputs.settings import params_file_text, PLANNER_SETTINGS
from threat_planner.errors import InputError, ScenarioError

DATA = Path(__file__).resolve().parents[1] / 'data'

FULL = {'cost': 'detection', 'max_detection': 0.05, 'speed': 25.0, 'scan_period': 2.0,
        'p_fa': 1.0e-4, 'swerling': 0, 'rcs': {'ellipsoid': [3.0, 1.0, 0.5]}}


def _good():
    return yaml.safe_load((DATA / 'uniform20_0.yaml').read_text())


def _with(**top):
    return {**_good(), **top}


def _refusal(**top):
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(_with(**top), 'trip.yaml')
    return str(err.value)


def test_the_block_gives_each_setting_by_its_config_field():
    sc = scenario_from_dict(_with(detection=FULL))
    assert sc.speed == 25.0
    assert sc.detection == {'cost_model': 'detection', 'max_detection': 0.05,
                            'scan_period_s': 2.0, 'p_fa': 1.0e-4, 'swerling': 0,
                            'rcs': 'ellipsoid 3.0 1.0 0.5'}
    # Each value is what its setting takes: it makes a valid PlannerConfig.
    PlannerConfig(**sc.detection).validated()


def test_without_the_block_the_scenario_leaves_the_settings_alone():
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    assert sc.detection == {} and 'detection' not in sc.to_dict()
    assert scenario_from_dict(_with(detection=None)).detection == {}
    assert scenario_from_dict(_with(detection={})).detection == {}


@pytest.mark.parametrize('rcs, text', [({'constant': 2}, 'constant 2.0'),
                                       ('ellipsoid 3, 1, 0.5', 'ellipsoid 3.0 1.0 0.5'),
                                       ('constant 0.1', 'constant 0.1')])
def test_rcs_is_a_mapping_or_the_setting_s_text(rcs, text):
    assert scenario_from_dict(_with(detection={'rcs': rcs})).detection == {'rcs': text}


def test_a_save_keeps_the_block_and_reads_back_the_same(tmp_path):
    sc = scenario_from_dict(_with(detection=FULL))
    save_scenario(sc, tmp_path / 'again.yaml')
    written = yaml.safe_load((tmp_path / 'again.yaml').read_text())
    assert written['detection'] == {'cost': 'detection', 'max_detection': 0.05,
                                    'scan_period': 2.0, 'p_fa': 1.0e-4, 'swerling': 0,
                                    'rcs': {'ellipsoid': [3.0, 1.0, 0.5]}}
    assert written['speed'] == 25.0   # one cruise speed, written at the top level
    again = load_scenario(tmp_path / 'again.yaml')
    assert again.detection == sc.detection and again.speed == sc.speed


def test_a_constant_rcs_is_saved_as_one_number(tmp_path):
    sc = scenario_from_dict(_with(detection={'rcs': {'constant': 0.5}}))
    assert sc.to_dict()['detection'] == {'rcs': {'constant': 0.5}}


@pytest.mark.parametrize('block, message', [
    ({'swerling': 2}, 'detection.swerling: must be 0 or 1, got 2'),
    ({'swerling': 0.5}, 'detection.swerling: must be 0 or 1, got 0.5'),
    ({'swerling': True}, 'detection.swerling: must be 0 or 1, got True'),
    ({'p_fa': 0}, 'detection.p_fa: must satisfy 0 < p_fa < 1, got 0'),
    ({'p_fa': 1.0}, 'detection.p_fa: must satisfy 0 < p_fa < 1, got 1.0'),
    ({'p_fa': 'small'}, "detection.p_fa: must satisfy 0 < p_fa < 1, got 'small'"),
    ({'speed': 0}, 'detection.speed: must be finite and > 0 and <= 1000 [m/s], got 0'),
    ({'speed': -5.0}, 'detection.speed: must be finite and > 0 and <= 1000 [m/s], got -5.0'),
    ({'scan_period': 0},
     'detection.scan_period: must be finite and > 0 and <= 3600 [s], got 0'),
    ({'scan_period': -1.0},
     'detection.scan_period: must be finite and > 0 and <= 3600 [s], got -1.0'),
    ({'scan_period': float('nan')},
     'detection.scan_period: must be finite and > 0 and <= 3600 [s], got nan'),
    ({'max_detection': 0}, 'detection.max_detection: must be finite and > 0 and <= 1, got 0'),
    ({'cost': 'risk'}, "detection.cost: must be one of paper, detection, got 'risk'"),
    ({'rcs': {'ellipsoid': [1, 2]}}, 'detection.rcs: ellipsoid takes 3 values, got 2'),
    ({'rcs': {'sphere': 1}},
     "detection.rcs: kind must be one of constant, ellipsoid, got 'sphere'"),
    ({'rcs': {'constant': -1}},
     'detection.rcs: constant values must be finite, > 0 and <= 1e+06 [m^2], got -1'),
])
def test_a_bad_value_is_one_line_naming_the_key_as_written(block, message):
    text = _refusal(detection=block)
    assert text == f'trip.yaml: {message}'
    assert '\n' not in text


def test_an_unknown_key_in_the_block_names_it_and_the_nearest_known_one():
    text = _refusal(detection={'swerlin': 1})
    assert text.startswith('trip.yaml: unknown field "detection.swerlin"; did you mean '
                           '"swerling"?')
    assert 'scan_period' in text and '\n' not in text


def test_a_block_that_is_not_a_mapping_is_refused():
    assert _refusal(detection=[1]).startswith('trip.yaml: detection: must be a mapping of ')


@pytest.mark.parametrize('key', ['cost', 'max_detection', 'p_fa', 'swerling', 'rcs',
                                 'scan_period'])
def test_a_block_key_at_the_top_level_points_into_the_block(key):
    assert _refusal(**{key: 1}) == (f'trip.yaml: unknown field "{key}"; it goes in the '
                                    f'detection block: "detection.{key}"')


def test_detection_speed_and_speed_are_one_setting():
    assert scenario_from_dict(_with(detection={'speed': 12})).speed == 12.0
    assert scenario_from_dict(_with(speed=12, detection={'speed': 12.0})).speed == 12.0
    assert _refusal(speed=20, detection={'speed': 25}) == (
        'trip.yaml: speed: 20 and detection.speed: 25 differ; they are one setting '
        '(speed_mps): give one, or both alike')


def test_a_scenario_built_in_code_checks_its_detection_settings():
    base = load_scenario(DATA / 'uniform20_0.yaml')
    fields = dict(base.__dict__)
    with pytest.raises(InputError, match='swerling: must be 0 or 1, got 3'):
        Scenario(**{**fields, 'detection': {'swerling': 3}})
    with pytest.raises(InputError, match='not a detection setting: w'):
        Scenario(**{**fields, 'detection': {'w': 0.3}})


# ----------------------------------------------------------------- the settings


def test_swerling_and_rcs_say_their_rule_in_words():
    assert PLANNER_SETTINGS['swerling'].rule == 'must be 0 or 1'
    assert PLANNER_SETTINGS['rcs'].rule == "must be 'constant S' or 'ellipsoid A B C'"
    with pytest.raises(InputError, match=r'^swerling: must be 0 or 1, got 2$'):
        PlannerConfig(swerling=2).validated()
    with pytest.raises(InputError, match=r"^rcs: must be 'constant S' or 'ellipsoid A B C', "
                                         r"got 5$"):
        PlannerConfig(rcs=5).validated()


def test_the_params_file_writes_p_fa_as_a_float_yaml_reads_back():
    # PyYAML reads 1e-06 as the string '1e-06'; the file must hold a number.
    params = yaml.safe_load(params_file_text())['threat_planner']['ros__parameters']
    assert params['p_fa'] == 1.0e-6 and isinstance(params['p_fa'], float)


def test_cost_detection_needs_method_best():
    PlannerConfig(cost_model='detection').validated()   # method best, the default
    for method in ('paper', 'improved'):
        with pytest.raises(InputError) as err:
            PlannerConfig(cost_model='detection', method=method).validated()
        assert str(err.value) == (f"cost_model: detection needs method best, got method "
                                  f"'{method}' (set method best, or cost_model paper)")
    PlannerConfig(cost_model='paper', method='paper').validated()
