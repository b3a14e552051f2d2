"""Events files: what changes in flight, and when.

Layout (times in seconds from the start of the flight, non-decreasing)::

    events:
      - {t: 3.0, add_threat: {position: [x, y, z], intensity: F,
                              lethal_radius: r, velocity: [vx, vy, vz]}}
      - {t: 5.0, move_threat: {index: 2, position: [x, y, z], velocity: [vx, vy, vz]}}
      - {t: 6.0, remove_threat: {index: 1}}
      - {t: 7.0, add_zone: {type: sphere, center: [x, y, z], radius: r}}
      - {t: 8.0, goal: [x, y, z]}

``lethal_radius`` and ``velocity`` of an added threat are optional (none, still);
``move_threat`` takes either or both of ``position`` and ``velocity`` (the other stays).
Threat indices count the scenario's threats first, then the added ones in file order.
``add_zone`` takes any ``no_fly_zones`` entry of the scenario format.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
import re

import numpy as np
import yaml

from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.world.airspace import zone_from_mapping, Zone
from threat_planner.errors import InputError

__all__ = ['EVENT_KINDS', 'Event', 'apply_event', 'load_events', 'parse_events']

#: Each kind of event and the keys its mapping takes (required, optional).
EVENT_KINDS = {
    'add_threat': (('position', 'intensity'), ('lethal_radius', 'velocity')),
    'move_threat': (('index',), ('position', 'velocity')),
    'remove_threat': (('index',), ()),
    'add_zone': ((), ()),
    'goal': ((), ()),
}


@dataclass(frozen=True)
class Event:
    """One change at time ``t`` [s]: its kind and its validated values."""

    t: float
    kind: str
    values: dict
    label: str

    def describe(self) -> str:
        """Short text for replan reasons: ``add_threat #4 at t=3``."""
        index = self.values.get('index')
        return f'{self.kind}' + (f' #{index}' if index is not None else '') + \
            f' at t={self.t:g}'


def _vector(name: str, value: object) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise InputError(f'{name}: expected [x, y, z], got {value!r}')
    out = []
    for k, v in enumerate(value):
        out.append(_number(f'{name}[{k}]', v))
    return out


#: A number YAML 1.1 (PyYAML) leaves a string: an exponent without a sign, ``2.0e5``.
_YAML12_FLOAT = re.compile(r'[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][0-9]+')


def _number(name: str, value: object, positive: bool = False) -> float:
    if isinstance(value, str) and _YAML12_FLOAT.fullmatch(value.strip()):
        value = float(value)    # as a scenario's intensity reads it
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f'{name}: expected a number, got {value!r}')
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f'{name}: must be finite, got {v}')
    if positive and v <= 0:
        raise InputError(f'{name}: must be > 0, got {v:g}')
    return v


def _index(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError(f'{name}: expected a threat index >= 0, got {value!r}')
    return int(value)


def _event(i: int, raw: object) -> Event:
    where = f'events[{i}]'
    if not isinstance(raw, dict):
        raise InputError(f'{where}: expected a mapping like {{t: 3.0, add_threat: {{...}}}}')
    if 't' not in raw:
        raise InputError(f'{where}.t: missing')
    t = _number(f'{where}.t', raw['t'])
    if t < 0:
        raise InputError(f'{where}.t: must be >= 0, got {t:g}')
    kinds = [k for k in raw if k != 't']
    unknown = [k for k in kinds if k not in EVENT_KINDS]
    if unknown:
        raise InputError(f'{where}.{unknown[0]}: unknown key; expected t and one of '
                         f'{", ".join(EVENT_KINDS)}')
    if len(kinds) != 1:
        raise InputError(f'{where}: expected exactly one of {", ".join(EVENT_KINDS)}, got '
                         f'{len(kinds)}')
    kind = kinds[0]
    body = raw[kind]
    name = f'{where}.{kind}'
    if kind == 'goal':
        return Event(t, kind, {'goal': _vector(name, body)}, name)
    if kind == 'add_zone':
        zone = zone_from_mapping(body, name)
        return Event(t, kind, {'zone': zone}, name)
    if not isinstance(body, dict):
        raise InputError(f'{name}: expected a mapping')
    required, optional = EVENT_KINDS[kind]
    for key in body:
        if key not in required + optional:
            raise InputError(f'{name}.{key}: unknown key; expected '
                             f'{", ".join(required + optional)}')
    for key in required:
        if key not in body:
            raise InputError(f'{name}.{key}: missing')
    values: dict = {}
    for key, value in body.items():
        field = f'{name}.{key}'
        if key == 'index':
            values[key] = _index(field, value)
        elif key in ('position', 'velocity'):
            values[key] = _vector(field, value)
        else:
            values[key] = _number(field, value, positive=True)
    if kind == 'move_threat' and len(values) == 1:
        raise InputError(f'{name}: expected position or velocity (or both)')
    return Event(t, kind, values, name)


def parse_events(data: object) -> list[Event]:
    """Validate an events document (module docstring); return its events in time order.

    Raises
    ------
    InputError
        Naming the bad field (``events[3].add_threat.intensity``) and value.

    """
    if not isinstance(data, dict) or set(data) - {'events'}:
        extra = sorted(set(data) - {'events'}) if isinstance(data, dict) else []
        raise InputError(f'{extra[0]}: unknown key; an events file holds one key, events'
                         if extra else 'events file: expected a mapping with key events')
    raw = data.get('events') or []
    if not isinstance(raw, list):
        raise InputError('events: expected a list')
    out = [_event(i, r) for i, r in enumerate(raw)]
    for i in range(1, len(out)):
        if out[i].t < out[i - 1].t:
            raise InputError(f'events[{i}].t: {out[i].t:g} is before events[{i - 1}].t '
                             f'{out[i - 1].t:g}; events must be in time order')
    return out


def load_events(path: str | Path) -> list[Event]:
    """Read and validate an events YAML file."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise InputError(f'events: cannot read {p}: {exc.strerror}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f'events: {p} is not YAML ({str(exc).splitlines()[0]})') from None
    return parse_events(data)


def apply_event(event: Event, timeline: ThreatTimeline, zones: list[Zone]) -> np.ndarray | None:
    """Apply a threat or zone event in place; return the new goal of a goal event.

    Raises
    ------
    InputError
        For a move or removal of a threat that does not exist (or no longer does).

    """
    v = event.values
    if event.kind == 'add_threat':
        timeline.add(event.t, v['position'], v['intensity'], v.get('velocity', (0, 0, 0)),
                     v.get('lethal_radius', np.nan))
    elif event.kind in ('move_threat', 'remove_threat'):
        try:
            if event.kind == 'move_threat':
                timeline.move(event.t, v['index'], v.get('position'), v.get('velocity'))
            else:
                timeline.remove(event.t, v['index'])
        except InputError as exc:
            # The timeline names 'move_threat.index': the file's field is this event's.
            text = str(exc).removeprefix(f'{event.kind}.')
            raise InputError(f'{event.label}.{text}') from None
    elif event.kind == 'add_zone':
        zones.append(v['zone'])
    else:
        return np.asarray(v['goal'], float)
    return None
