"""Scenario files: every bundled file loads, bad files fail with one clear line."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from threat_planner.core.inputs.scenario import load_scenario, scenario_from_dict
from threat_planner.errors import ScenarioError

DATA = Path(__file__).resolve().parents[1] / 'data'


@pytest.mark.parametrize('path', sorted(DATA.glob('*.yaml')), ids=lambda p: p.stem)
def test_bundled_scenarios_load(path):
    sc = load_scenario(path)
    raw = yaml.safe_load(path.read_text())
    assert sc.name == raw['name'] and sc.frame_id == raw['frame_id']
    assert len(sc.threats) == len(raw['threats'])
    assert np.allclose(sc.threats.positions[0], raw['threats'][0]['position'])
    assert sc.box.contains(sc.start) and sc.box.contains(sc.goal)
    assert scenario_from_dict(sc.to_dict()).threats.positions.tolist() == \
        sc.threats.positions.tolist()


def _good():
    return yaml.safe_load((DATA / 'uniform20_0.yaml').read_text())


@pytest.mark.parametrize('mutate,expected', [
    (lambda d: d.pop('start'), 'missing field "start"'),
    (lambda d: d.pop('bounds'), 'missing field "bounds"'),
    (lambda d: d['threats'][2].__setitem__('intensity', 0.0), r'threats\[2\].intensity'),
    (lambda d: d['threats'][4].__setitem__('intensity', -3.0), r'threats\[4\].intensity'),
    (lambda d: d['threats'][1]['position'].__setitem__(0, float('nan')),
     r'threats.position\[1\]: not finite'),
    (lambda d: d['threats'][1].__setitem__('position', [1.0, 2.0]), r'threats\[1\].position'),
    (lambda d: d.__setitem__('goal', [100.0, 100.0, 500.0]), 'goal.*outside bounds'),
    (lambda d: d.__setitem__('start', [float('inf'), 0, 0]), 'start: not finite'),
    (lambda d: d['bounds'].__setitem__('max', [100.0, -1.0, 100.0]), 'bounds: max.y'),
    (lambda d: d['threats'][0].pop('intensity'), r'threats\[0\] needs'),
])
def test_bad_fields_name_the_file_and_the_field(tmp_path, mutate, expected):
    data = _good()
    mutate(data)
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ScenarioError, match=expected) as info:
        load_scenario(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and '\n' not in msg


def test_unreadable_and_invalid_files(tmp_path):
    with pytest.raises(ScenarioError, match='cannot read'):
        load_scenario(tmp_path / 'missing.yaml')
    bad = tmp_path / 'broken.yaml'
    bad.write_text('name: [unclosed\n')
    with pytest.raises(ScenarioError, match='not valid YAML'):
        load_scenario(bad)
    scalar = tmp_path / 'scalar.yaml'
    scalar.write_text('42\n')
    with pytest.raises(ScenarioError, match='mapping'):
        load_scenario(scalar)


@pytest.mark.parametrize('edit, expected', [
    (lambda d: d.update(frameid='map'), 'unknown field "frameid"; did you mean "frame_id"'),
    (lambda d: d.update(nmae='x'), 'unknown field "nmae"; did you mean "name"'),
    (lambda d: d['threats'][0].update(radius=3.0),
     'unknown field "threats\\[0\\].radius"; did you mean "lethal_radius"'),
    (lambda d: d['bounds'].update(maxx=[1, 1, 1]), 'unknown field "bounds.maxx"; did you mean'),
    (lambda d: d.update(colour='red'), 'unknown field "colour" \\(known: name'),
])
def test_unknown_keys_are_named_with_a_suggestion(edit, expected):
    data = load_scenario(DATA / 'uniform20_0.yaml').to_dict()
    edit(data)
    with pytest.raises(ScenarioError, match=expected):
        scenario_from_dict(data, 'f.yaml')


def test_airspace_keys_are_known():
    data = load_scenario(DATA / 'uniform20_0.yaml').to_dict()
    data.update(no_fly_zones=[], terrain=None, lethal_radius=1.0)
    data['threats'][0]['lethal_radius'] = 2.0
    assert len(scenario_from_dict(data).threats) == 20


def test_bad_values_print_as_plain_numbers():
    data = load_scenario(DATA / 'uniform20_0.yaml').to_dict()
    data['threats'][0]['intensity'] = -5.0
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data, 'f.yaml')
    assert '-5.0' in str(info.value) and 'np.' not in str(info.value)
