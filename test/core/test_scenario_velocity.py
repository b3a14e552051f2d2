"""The scenario key ``velocity`` of a threat [m/s]: checked, exposed, saved back, flown."""

from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
import yaml

from threat_planner.core.inputs.scenario import (load_scenario, save_scenario, Scenario,
                                                 scenario_from_dict)
from threat_planner.errors import InputError, ScenarioError
from threat_planner.flight.fly import scenario_timeline

DATA = Path(__file__).resolve().parents[1] / 'data'


def _good():
    return yaml.safe_load((DATA / 'uniform20_0.yaml').read_text())


def _with(velocities):
    """The bundled scenario with ``velocity`` set on the threats of `velocities`."""
    doc = _good()
    for i, v in velocities.items():
        doc['threats'][i]['velocity'] = v
    return doc


def test_without_the_key_every_threat_is_still_and_nothing_is_saved():
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    assert sc.velocities.shape == (20, 3) and sc.velocities.dtype == float
    assert not np.any(sc.velocities)
    assert all('velocity' not in t for t in sc.to_dict()['threats'])
    assert not scenario_timeline(sc).moving()


def test_velocities_load_in_threat_order_and_zeros_elsewhere():
    sc = scenario_from_dict(_with({3: [5, -2.5, 0], 17: [0.0, 0.0, 1e3]}))
    want = np.zeros((20, 3))
    want[3], want[17] = [5.0, -2.5, 0.0], [0.0, 0.0, 1000.0]
    assert np.array_equal(sc.velocities, want)
    timeline = scenario_timeline(sc)
    assert timeline.moving()
    # Threat 3 is 10 s later where its velocity takes it.
    at = timeline.snapshot(10.0)
    k = int(np.flatnonzero(at.ids == 3)[0])
    assert at.field.positions[k] == pytest.approx(sc.threats.positions[3] + [50.0, -25.0, 0])


def test_a_save_round_trip_keeps_the_velocities_bit_for_bit(tmp_path):
    rng = np.random.default_rng(44)
    vel = {int(i): rng.uniform(-30, 30, 3).tolist() for i in rng.choice(20, 5, replace=False)}
    sc = scenario_from_dict(_with(vel))
    save_scenario(sc, tmp_path / 'moving.yaml')
    back = load_scenario(tmp_path / 'moving.yaml')
    assert np.array_equal(back.velocities, sc.velocities)
    assert np.array_equal(back.threats.positions, sc.threats.positions)
    saved = yaml.safe_load((tmp_path / 'moving.yaml').read_text())['threats']
    # Only the threats that move carry the key.
    assert sorted(i for i, t in enumerate(saved) if 'velocity' in t) == sorted(vel)


def test_a_save_of_still_threats_writes_no_velocity(tmp_path):
    sc = scenario_from_dict(_with({2: [0, 0, 0]}))
    save_scenario(sc, tmp_path / 'still.yaml')
    assert 'velocity' not in (tmp_path / 'still.yaml').read_text()
    assert not np.any(load_scenario(tmp_path / 'still.yaml').velocities)


def test_a_threats_table_cannot_hold_velocities(tmp_path):
    sc = scenario_from_dict(_with({0: [1, 0, 0]}))
    with pytest.raises(InputError, match='threats_file: threat velocities need the threats '
                                         'list'):
        save_scenario(sc, tmp_path / 'big.yaml', threats_file='big.npy')


def test_the_constructor_takes_none_or_one_row_per_threat():
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    built = Scenario(sc.name, sc.frame_id, '', sc.box, sc.start, sc.goal, sc.threats)
    assert built.velocities.shape == (20, 3) and not np.any(built.velocities)
    with pytest.raises(InputError, match=r'threats.velocity: expected 20 rows .* got shape '
                                         r'\[3, 3\]'):
        Scenario(sc.name, sc.frame_id, '', sc.box, sc.start, sc.goal, sc.threats,
                 velocities=np.ones((3, 3)))


@pytest.mark.parametrize('value, message', [
    ([1, float('nan'), 0], 'must be finite, got [1, nan, 0]'),
    ([float('inf'), 0, 0], 'must be finite, got [inf, 0, 0]'),
    ([800, 800, 0], 'speed must be <= 1000 [m/s], got [800, 800, 0] (speed 1131.37)'),
    ([1, 2], 'expected [vx, vy, vz] [m/s], got [1, 2]'),
    ([1, 'fast', 0], "expected [vx, vy, vz] [m/s], got [1, 'fast', 0]"),
    ([True, 0, 0], 'expected [vx, vy, vz] [m/s], got [True, 0, 0]'),
    (5, 'expected [vx, vy, vz] [m/s], got 5'),
    (None, 'expected [vx, vy, vz] [m/s], got None'),
])
def test_a_bad_velocity_is_refused_naming_the_threat_and_the_value(value, message):
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(_with({7: value}), 'trip.yaml')
    assert str(err.value) == f'trip.yaml: threats[7].velocity: {message}'


def test_a_misspelt_key_points_at_velocity():
    doc = _good()
    doc['threats'][4]['velocty'] = [1, 0, 0]
    with pytest.raises(ScenarioError, match=r'unknown field "threats\[4\].velocty"; did you '
                                            r'mean "velocity"'):
        scenario_from_dict(doc)


@pytest.mark.parametrize('value, message', [
    ('[0, .nan, 0]', 'threats[1].velocity: must be finite, got [0, nan, 0]'),
    ('[0, 0, -1001]', 'threats[1].velocity: speed must be <= 1000 [m/s], got [0, 0, -1001]'),
])
def test_a_bad_velocity_on_the_command_line_exits_2_with_one_line(tmp_path, value, message):
    text = (DATA / 'uniform20_0.yaml').read_text()
    lines = text.splitlines()
    # The second threat's 'intensity' line: a velocity key beside it.
    at = [k for k, line in enumerate(lines) if line.startswith('  intensity:')][1]
    lines.insert(at + 1, f'  velocity: {value}')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('\n'.join(lines) + '\n')
    p = subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'plan', str(bad)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert 'Traceback' not in p.stderr
    err = p.stderr.strip().splitlines()
    assert len(err) == 1 and message in err[0], p.stderr
    assert err[0].startswith(f'threat-planner: error: {bad}: ')
