"""Events files: validated field by field, errors naming the field; applied to the timeline."""

from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
import yaml

from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError
from threat_planner.flight.events import apply_event, load_events, parse_events

DATA = Path(__file__).resolve().parents[1] / 'data'
SCENARIO = DATA / 'uniform20_0.yaml'

#: The issue's example, as written there (``2.0e5``: a string to YAML 1.1).
EXAMPLE = """
events:
  - {t: 2.0, add_threat: {position: [50, 50, 50], intensity: 2.0e5, lethal_radius: 8.0,
                          velocity: [0, 0, 0]}}
  - {t: 3.0, move_threat: {index: 0, position: [40, 40, 40], velocity: [1, 2, 3]}}
  - {t: 4.0, remove_threat: {index: 3}}
  - {t: 5.0, add_zone: {type: sphere, center: [60, 60, 60], radius: 10}}
  - {t: 6.0, goal: [90, 90, 50]}
"""


def _doc(*events):
    return {'events': list(events)}


def test_the_issue_s_example_reads_in_time_order_with_its_values(tmp_path):
    (tmp_path / 'ev.yaml').write_text(EXAMPLE)
    events = load_events(tmp_path / 'ev.yaml')
    assert [(e.t, e.kind) for e in events] == [
        (2.0, 'add_threat'), (3.0, 'move_threat'), (4.0, 'remove_threat'),
        (5.0, 'add_zone'), (6.0, 'goal')]
    assert events[0].values == {'position': [50.0, 50.0, 50.0], 'intensity': 2.0e5,
                                'lethal_radius': 8.0, 'velocity': [0.0, 0.0, 0.0]}
    assert events[1].values == {'index': 0, 'position': [40.0, 40.0, 40.0],
                                'velocity': [1.0, 2.0, 3.0]}
    assert events[4].values == {'goal': [90.0, 90.0, 50.0]}
    assert events[1].describe() == 'move_threat #0 at t=3'
    assert events[0].label == 'events[0].add_threat'


def test_an_empty_file_or_list_has_no_events():
    assert parse_events({'events': []}) == []
    assert parse_events({'events': None}) == []


@pytest.mark.parametrize('doc, message', [
    ({'evnts': []}, 'evnts: unknown key; an events file holds one key, events'),
    ([1, 2], 'events file: expected a mapping with key events'),
    ({'events': {'t': 1}}, 'events: expected a list'),
    (_doc({'t': 1.0, 'add_thret': {}}),
     'events[0].add_thret: unknown key; expected t and one of add_threat, move_threat'),
    (_doc({'t': 1.0, 'remove_threat': {'index': 1}},
          {'t': 2.0, 'add_threat': {'position': [1, 2, 3], 'intensity': 1e5,
                                    'radius': 3}}),
     'events[1].add_threat.radius: unknown key; expected position, intensity, '
     'lethal_radius, velocity'),
    (_doc({'t': 1.0, 'move_threat': {'index': 1, 'speed': [1, 0, 0]}}),
     'events[0].move_threat.speed: unknown key; expected index, position, velocity'),
    (_doc({'add_threat': {}}), 'events[0].t: missing'),
    (_doc({'t': 1.0, 'add_threat': {'position': [1, 2, 3]}}),
     'events[0].add_threat.intensity: missing'),
    (_doc({'t': 1.0, 'goal': [1, 2, 3], 'remove_threat': {'index': 0}}),
     'events[0]: expected exactly one of'),
    (_doc({'t': 1.0}), 'events[0]: expected exactly one of'),
    (_doc({'t': 3.0, 'goal': [1, 2, 3]}, {'t': 4.0, 'goal': [1, 2, 3]},
          {'t': 1.5, 'goal': [1, 2, 3]}),
     'events[2].t: 1.5 is before events[1].t 4; events must be in time order'),
    (_doc({'t': float('nan'), 'goal': [1, 2, 3]}), 'events[0].t: must be finite, got nan'),
    (_doc({'t': -1, 'goal': [1, 2, 3]}), 'events[0].t: must be >= 0, got -1'),
    (_doc({'t': 1, 'goal': [1, float('nan'), 3]}), 'events[0].goal[1]: must be finite, got nan'),
    (_doc({'t': 1, 'add_threat': {'position': [1, 2, float('inf')], 'intensity': 1e5}}),
     'events[0].add_threat.position[2]: must be finite, got inf'),
    (_doc({'t': 1, 'add_threat': {'position': [1, 2, 3], 'intensity': float('nan')}}),
     'events[0].add_threat.intensity: must be finite, got nan'),
    (_doc({'t': 1, 'add_threat': {'position': [1, 2, 3], 'intensity': -5}}),
     'events[0].add_threat.intensity: must be > 0, got -5'),
    (_doc({'t': 1, 'add_threat': {'position': [1, 2, 3], 'intensity': 1e5,
                                  'lethal_radius': 0}}),
     'events[0].add_threat.lethal_radius: must be > 0, got 0'),
    (_doc({'t': 1, 'move_threat': {'index': 2, 'velocity': [1, 2]}}),
     'events[0].move_threat.velocity: expected [x, y, z], got [1, 2]'),
    (_doc({'t': 1, 'move_threat': {'index': 2}}),
     'events[0].move_threat: expected position or velocity (or both)'),
    (_doc({'t': 1, 'goal': [1, 2, 3]}, {'t': 1, 'goal': [1, 2, 3]},
          {'t': 2, 'move_threat': {'index': -1, 'position': [1, 2, 3]}}),
     'events[2].move_threat.index: expected a threat index >= 0, got -1'),
    (_doc({'t': 1, 'remove_threat': {'index': 1.5}}),
     'events[0].remove_threat.index: expected a threat index >= 0, got 1.5'),
    (_doc({'t': 1, 'remove_threat': {'index': True}}),
     'events[0].remove_threat.index: expected a threat index >= 0, got True'),
    (_doc({'t': 1, 'goal': 'home'}), "events[0].goal: expected [x, y, z], got 'home'"),
    (_doc({'t': 'soon', 'goal': [1, 2, 3]}), "events[0].t: expected a number, got 'soon'"),
])
def test_a_bad_document_is_refused_naming_the_field(doc, message):
    with pytest.raises(InputError) as err:
        parse_events(doc)
    assert str(err.value).startswith(message), str(err.value)
    assert '\n' not in str(err.value)


def test_a_bad_zone_names_the_event():
    with pytest.raises(InputError, match=r'^events\[0\]\.add_zone'):
        parse_events(_doc({'t': 1, 'add_zone': {'type': 'sphere', 'center': [1, 2, 3],
                                                'radius': -2}}))


def test_a_file_that_is_not_yaml_or_not_there_names_the_file(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('events: [ {t: 1\n')
    with pytest.raises(InputError, match=f'^events: {bad} is not YAML'):
        load_events(bad)
    with pytest.raises(InputError, match='^events: cannot read .*missing.yaml'):
        load_events(tmp_path / 'missing.yaml')


def _timeline():
    field = ThreatField.from_arrays([[0.0, 0, 0], [10.0, 0, 0], [20.0, 0, 0]], [1e5, 2e5, 3e5])
    return ThreatTimeline(field)


def test_events_apply_to_the_timeline_indices_counting_added_threats_last():
    tl, zones = _timeline(), []
    events = parse_events(yaml.safe_load(EXAMPLE.replace('index: 3', 'index: 1')))
    goal = None
    for e in events:
        new_goal = apply_event(e, tl, zones)
        assert (new_goal is None) == (e.kind != 'goal')
        goal = goal if new_goal is None else new_goal
    assert goal.tolist() == [90.0, 90.0, 50.0]
    assert len(zones) == 1 and zones[0].radius == 10.0
    at = tl.snapshot(10.0)
    ids = at.ids.tolist()
    assert sorted(ids) == [0, 2, 3]          # threat 1 removed at 4 s, threat 3 popped up
    pos = dict(zip(ids, at.field.positions.tolist()))
    assert pos[0] == pytest.approx([47.0, 54.0, 61.0])   # moved at 3 s, then 7 s at (1, 2, 3)
    assert pos[3] == [50.0, 50.0, 50.0]
    lethal = dict(zip(ids, at.lethal.tolist()))
    assert lethal[3] == 8.0 and np.isnan(lethal[0])


@pytest.mark.parametrize('event, message', [
    ({'t': 1, 'move_threat': {'index': 3, 'velocity': [1, 0, 0]}},
     'events[0].move_threat.index: threat 3 does not exist (3 threats so far)'),
    ({'t': 1, 'remove_threat': {'index': 7}},
     'events[0].remove_threat.index: threat 7 does not exist (3 threats so far)'),
])
def test_a_threat_that_does_not_exist_is_named_by_the_event_s_field(event, message):
    (e,) = parse_events(_doc(event))
    with pytest.raises(InputError) as err:
        apply_event(e, _timeline(), [])
    assert str(err.value) == message


def test_a_removed_threat_cannot_move_again():
    tl = _timeline()
    gone, moved = parse_events(_doc({'t': 1, 'remove_threat': {'index': 1}},
                                    {'t': 2, 'move_threat': {'index': 1,
                                                             'position': [1, 2, 3]}}))
    apply_event(gone, tl, [])
    with pytest.raises(InputError, match=r'^events\[1\]\.move_threat\.index: threat 1 was '
                                         r'removed'):
        apply_event(moved, tl, [])


def _fly(tmp_path, text):
    ev = tmp_path / 'ev.yaml'
    ev.write_text(text)
    return subprocess.run([sys.executable, '-m', 'threat_planner.cli', 'fly', str(SCENARIO),
                           '--events', str(ev)], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize('text, message', [
    ('events:\n  - {t: 1.0, add_threat: {position: [1, 2, 3], intensity: 1e5, colour: 1}}\n',
     'events[0].add_threat.colour: unknown key'),
    ('events:\n  - {t: 3.0, goal: [50, 50, 50]}\n  - {t: 2.0, goal: [60, 60, 60]}\n',
     'events[1].t: 2 is before events[0].t 3'),
    ('events:\n  - {t: .nan, goal: [50, 50, 50]}\n', 'events[0].t: must be finite, got nan'),
    ('events:\n  - {t: 1.0, remove_threat: {index: 0}}\n'
     '  - {t: 1.0, goal: [50, 50, 50]}\n  - {t: 2.0, move_threat: {index: 20, '
     'velocity: [1, 0, 0]}}\n',
     'events[2].move_threat.index: threat 20 does not exist (20 threats so far)'),
    ('events:\n  - {t: 1.0, goal: [500, 50, 50]}\n', 'events[0].goal: [500.0, 50.0, 50.0] '
                                                     'is outside bounds'),
])
def test_the_command_line_exits_2_with_one_line_naming_the_field(tmp_path, text, message):
    p = _fly(tmp_path, text)
    assert p.returncode == 2, p.stdout + p.stderr
    assert 'Traceback' not in p.stderr and p.stdout == ''
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], p.stderr


def test_the_example_of_docs_flight_md_reads():
    text = (Path(__file__).resolve().parents[2] / 'docs' / 'flight.md').read_text()
    block = text.split('## Events files', 1)[1].split('```yaml\n', 1)[1].split('```', 1)[0]
    events = parse_events(yaml.safe_load(block))
    assert [e.kind for e in events] == ['add_threat', 'move_threat', 'remove_threat',
                                        'add_zone', 'goal']
