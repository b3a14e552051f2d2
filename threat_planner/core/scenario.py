"""Scenario files: the flight box, start, goal and threats, in YAML.

Layout (as in the bundled ``test/data/*.yaml``)::

    name: uniform20_0
    frame_id: map
    description: optional text
    bounds: {min: [x, y, z], max: [x, y, z]}
    start: [x, y, z]
    goal: [x, y, z]
    threats:
      - {position: [x, y, z], intensity: F}   # optional lethal_radius: r

and optionally ``no_fly_zones`` and ``terrain`` (see :mod:`threat_planner.core.airspace`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import difflib
from pathlib import Path

import numpy as np
import yaml

from threat_planner.core.airspace import Airspace
from threat_planner.errors import InputError, ScenarioError
from threat_planner.core.planner import check_endpoints
from threat_planner.core.threats import Box, ThreatField


@dataclass(frozen=True)
class Scenario:
    """A planning problem.

    Attributes:
        name: Scenario name.
        frame_id: Frame of every coordinate.
        description: Free text.
        box: Flight box.
        start: Start point (3,) [m].
        goal: Goal point (3,) [m].
        threats: The threat field.
    """

    name: str
    frame_id: str
    description: str
    box: Box
    start: np.ndarray
    goal: np.ndarray
    threats: ThreatField
    airspace: Airspace = field(default_factory=Airspace)

    def to_dict(self) -> dict:
        """Return the scenario in the YAML file layout."""
        out = {
            'name': self.name, 'frame_id': self.frame_id, 'description': self.description,
            'bounds': {'min': self.box.lo.tolist(), 'max': self.box.hi.tolist()},
            'start': self.start.tolist(), 'goal': self.goal.tolist(),
            'threats': [{'position': p.tolist(), 'intensity': float(f)}
                        for p, f in zip(self.threats.positions, self.threats.intensities)],
        }
        if self.airspace:
            lethal = self.airspace.lethal_radii(len(self.threats))
            for t, r in zip(out['threats'], lethal):
                if np.isfinite(r):
                    t['lethal_radius'] = float(r)
            out.update(self.airspace.to_mapping())
        return out


#: Keys a scenario file may hold; the airspace keys are read by the airspace layer.
TOP_KEYS = ('name', 'frame_id', 'description', 'bounds', 'start', 'goal', 'threats',
            'no_fly_zones', 'terrain', 'lethal_radius')
BOUNDS_KEYS = ('min', 'max')
THREAT_KEYS = ('position', 'intensity', 'lethal_radius')


def _check_keys(mapping: dict, known: tuple, where: str, fail) -> None:
    """Refuse an unknown (often misspelt) key, naming it and the nearest known one."""
    for key in mapping:
        if key in known:
            continue
        close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        hint = f'; did you mean "{close[0]}"?' if close else ''
        raise fail(f'unknown field "{where}{key}"{hint} (known: {", ".join(known)})')


def scenario_from_dict(data: object, source: str = '<dict>') -> Scenario:
    """Build and validate a Scenario from parsed YAML.

    Args:
        data: The parsed document.
        source: Where it came from, for error messages.

    Returns:
        The Scenario.

    Raises:
        ScenarioError: one line naming the source and the bad field.
    """
    def fail(msg: str) -> ScenarioError:
        return ScenarioError(f'{source}: {msg}')

    if not isinstance(data, dict):
        raise fail('expected a mapping at the top level')
    _check_keys(data, TOP_KEYS, '', fail)
    for key in ('bounds', 'start', 'goal', 'threats'):
        if key not in data:
            raise fail(f'missing field "{key}"')
    bounds = data['bounds']
    if not isinstance(bounds, dict) or 'min' not in bounds or 'max' not in bounds:
        raise fail('field "bounds" needs "min" and "max"')
    _check_keys(bounds, BOUNDS_KEYS, 'bounds.', fail)
    threats = data['threats'] if data['threats'] is not None else []
    if not isinstance(threats, list):
        raise fail('field "threats" must be a list')
    positions, intensities, lethal = [], [], []
    for i, t in enumerate(threats):
        if not isinstance(t, dict) or 'position' not in t or 'intensity' not in t:
            raise fail(f'threats[{i}] needs "position" and "intensity"')
        _check_keys(t, THREAT_KEYS, f'threats[{i}].', fail)
        positions.append(t['position'])
        intensities.append(t['intensity'])
        lethal.append(t.get('lethal_radius', float('nan')))
    try:
        for i, p in enumerate(positions):
            if not isinstance(p, (list, tuple)) or len(p) != 3:
                raise InputError(f'threats[{i}].position: expected [x, y, z], got {p!r}')
        box = Box.from_corners(bounds['min'], bounds['max'])
        threat_field = ThreatField.from_arrays(
            np.array(positions, dtype=float).reshape(-1, 3), np.array(intensities, dtype=float))
        start, goal = check_endpoints(data['start'], data['goal'], box, threat_field)
        base = None if source.startswith('<') else Path(source).parent
        airspace = Airspace.from_mapping(
            {k: data[k] for k in ('no_fly_zones', 'terrain') if k in data}, base,
            lethal_radii=[float('nan') if r is None else r for r in lethal],
            threat_positions=threat_field.positions)
        airspace.check_point('start', start)
        airspace.check_point('goal', goal)
    except InputError as exc:
        raise fail(str(exc)) from None
    except (TypeError, ValueError, OverflowError) as exc:
        raise fail(f'bad value ({exc})') from None
    return Scenario(str(data.get('name', Path(source).stem)), str(data.get('frame_id', 'map')),
                    str(data.get('description', '') or ''), box, start, goal, threat_field,
                    airspace)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file.

    Args:
        path: File path.

    Returns:
        The Scenario.

    Raises:
        ScenarioError: one line naming the file and the bad field.
    """
    path = Path(path)
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise ScenarioError(f'{path}: cannot read ({exc.strerror})') from None
    try:
        # libyaml's C loader when built in: 10,000 threats load in a fraction of the time.
        data = yaml.load(text, Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    except (yaml.YAMLError, ValueError, RecursionError) as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark else ''
        raise ScenarioError(f'{path}: not valid YAML{where}') from None
    return scenario_from_dict(data, str(path))
