"""The scenario key ``speed``: a cruise speed [m/s] checked as the setting, kept on save."""

from pathlib import Path

import pytest
import yaml

from threat_planner.core.inputs.scenario import load_scenario, save_scenario, scenario_from_dict
from threat_planner.errors import ScenarioError

DATA = Path(__file__).resolve().parents[1] / 'data'


def _good():
    return yaml.safe_load((DATA / 'uniform20_0.yaml').read_text())


def test_without_the_key_the_scenario_leaves_the_speed_to_the_setting():
    assert load_scenario(DATA / 'uniform20_0.yaml').speed is None
    assert 'speed' not in load_scenario(DATA / 'uniform20_0.yaml').to_dict()


@pytest.mark.parametrize('value', [12, 12.5, 1000])
def test_a_speed_loads_as_a_float_and_saves_back(tmp_path, value):
    sc = scenario_from_dict({**_good(), 'speed': value})
    assert sc.speed == float(value) and isinstance(sc.speed, float)
    save_scenario(sc, tmp_path / 'again.yaml')
    assert load_scenario(tmp_path / 'again.yaml').speed == float(value)


@pytest.mark.parametrize('value, shown', [
    (0, '0'), (-4.0, '-4.0'), (float('nan'), 'nan'), (float('inf'), 'inf'),
    (1000.5, '1000.5'), ('fast', "'fast'"), (True, 'True'), (None, 'None'), ([20], '[20]')])
def test_a_bad_speed_is_refused_naming_the_key_and_the_value(value, shown):
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict({**_good(), 'speed': value}, 'trip.yaml')
    assert str(err.value) == (f'trip.yaml: speed: must be finite and > 0 and <= 1000 [m/s], '
                              f'got {shown}')


def test_a_misspelt_key_points_at_speed():
    with pytest.raises(ScenarioError, match='unknown field "sped"; did you mean "speed"'):
        scenario_from_dict({**_good(), 'sped': 20})
