"""Scenario files: the flight box, start, goal and threats, in YAML.

Layout (as in the bundled ``test/data/*.yaml``)::

    name: uniform20_0
    frame_id: map
    description: optional text
    bounds: {min: [x, y, z], max: [x, y, z]}
    start: [x, y, z]
    goal: [x, y, z]
    threats:
      - {position: [x, y, z], intensity: F}   # optional lethal_radius: r, velocity

and optionally ``no_fly_zones`` and ``terrain`` (see :mod:`threat_planner.core.world.airspace`).
Big threat pictures may instead name a compact file next to the YAML, ``threats_file:
threats.npy`` (an (N, 4) float array) or ``threats.csv`` (comma-separated, ``#`` comments,
an optional header line), columns x y z F: it loads in milliseconds where 10,000 YAML
mappings take seconds even with libyaml.

``datum: [lat, lon, h]`` ties the local frame to WGS84 (East-North-Up at the datum), so
plans can be exported with latitudes and longitudes; with ``coordinates: geodetic`` every
position of the file is given in WGS84 (:mod:`threat_planner.core.inputs.geodetic`), and
``terrain: {dem: FILE.tif}`` reads a GeoTIFF DEM (:mod:`threat_planner.core.geo.dem`).
``speed: V`` [m/s] is the cruise speed the plan is flown at (the setting ``speed_mps``,
which a command line's ``--speed`` overrides); it times the path and changes no plan.
A threat's ``velocity: [vx, vy, vz]`` [m/s] (finite, at most MAX_THREAT_SPEED; East,
North, Up in a geodetic file) moves it in straight lines from t = 0 for a plan in time
or a flight (:mod:`threat_planner.core.flight`); a static plan uses the positions as given.

The block ``detection`` (issue 43) holds the radar model every plan's P_detect is reported
under, and the choice of the cost; each key is a setting, which the command line's option
overrides (as ``speed``)::

    detection:
      cost: detection        # cost_model, --cost: 'paper' (the default) or 'detection'
      max_detection: 0.05    # max_detection, --max-detection: 0 < P <= 1 (1 = no bound)
      speed: 20.0            # speed_mps, --speed [m/s]: the top-level speed, in one place
      scan_period: 1.0       # scan_period_s, --scan-period [s]
      p_fa: 1.0e-6           # p_fa, --p-fa: 0 < p_fa < 1
      swerling: 1            # swerling, --swerling: 0 or 1
      rcs: {ellipsoid: [3.0, 1.0, 0.5]}   # rcs, --rcs: or {constant: 1.0} [m^2]

Every key is optional. The objective (``cost``, ``max_detection``) lives in the block, not
at the top level: it is the detection model's. ``detection.speed`` and the top-level
``speed`` are one setting; a file may give both only with the same value, and a saved
scenario writes it at the top level. A bad value is refused in one line naming the key as
written (``detection.swerling: must be 0 or 1, got 2``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import numbers
from pathlib import Path
from typing import Optional
import warnings

import numpy as np
import yaml

from threat_planner.core.geo.frames import Datum
from threat_planner.core.inputs.geodetic import dem_terrain, frame_of, to_local
from threat_planner.core.inputs.scenario_detection import (
    BLOCK_ONLY, check_keys, DETECTION_SETTINGS, detection_of, file_block, speed_of)
from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.core.inputs.yaml_threats import load_document
from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.threats import Box, check_endpoints, ThreatField
from threat_planner.errors import InputError, ScenarioError


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
        airspace: No-fly zones and terrain.
        datum: WGS84 origin of the frame (East-North-Up), or None.
        speed: Cruise speed [m/s] the file gives (key ``speed``), or None for the
            setting's.
        velocities: Each threat's velocity (N, 3) [m/s] (key ``velocity``); zeros where a
            threat has none (None in the constructor: all still).
        detection: The settings the ``detection`` block gives, by PlannerConfig field
            (``cost_model``, ``max_detection``, ``scan_period_s``, ``p_fa``, ``swerling``,
            ``rcs`` as the setting's text); its ``speed`` is :attr:`speed`. Empty: none.
    """

    name: str
    frame_id: str
    description: str
    box: Box
    start: np.ndarray
    goal: np.ndarray
    threats: ThreatField
    airspace: Airspace = field(default_factory=Airspace)
    datum: Optional[Datum] = None
    speed: Optional[float] = None
    velocities: Optional[np.ndarray] = None
    detection: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Hold the velocities as an (N, 3) float array, zeros for None; check detection."""
        unknown = sorted(set(self.detection) - set(DETECTION_SETTINGS.values()))
        if unknown:
            raise InputError(f'detection: not a detection setting: {", ".join(unknown)} '
                             f'(known: {", ".join(DETECTION_SETTINGS.values())})')
        for name, value in self.detection.items():
            PLANNER_SETTINGS[name].check(value)
        n = len(self.threats)
        vel = np.zeros((n, 3)) if self.velocities is None else np.array(
            self.velocities, dtype=float)
        if vel.shape != (n, 3) and not (n == 0 and vel.size == 0):
            raise InputError(f'threats.velocity: expected {n} rows [vx, vy, vz], got shape '
                             f'{list(vel.shape)}')
        object.__setattr__(self, 'velocities', vel.reshape(n, 3))

    def to_dict(self) -> dict:
        """Return the scenario in the YAML file layout (local coordinates)."""
        out = {
            'name': self.name, 'frame_id': self.frame_id, 'description': self.description,
            **({} if self.datum is None else {'datum': self.datum.as_list()}),
            'bounds': {'min': self.box.lo.tolist(), 'max': self.box.hi.tolist()},
            'start': self.start.tolist(), 'goal': self.goal.tolist(),
            'threats': [{'position': p.tolist(), 'intensity': float(f)}
                        for p, f in zip(self.threats.positions, self.threats.intensities)],
            **({} if self.speed is None else {'speed': self.speed}),
        }
        if self.detection:
            out['detection'] = file_block(self.detection)
        for t, v in zip(out['threats'], self.velocities):
            if np.any(v != 0):
                t['velocity'] = v.tolist()
        if self.airspace:
            lethal = self.airspace.lethal_radii(len(self.threats))
            for t, r in zip(out['threats'], lethal):
                if np.isfinite(r):
                    t['lethal_radius'] = float(r)
            out.update(self.airspace.to_mapping())
        return out


#: Keys a scenario file may hold; the airspace keys are read by the airspace layer.
TOP_KEYS = ('name', 'frame_id', 'description', 'bounds', 'start', 'goal', 'threats',
            'threats_file', 'no_fly_zones', 'terrain', 'lethal_radius', 'datum',
            'coordinates', 'speed', 'detection')
#: Suffixes a ``threats_file`` may have.
THREATS_FILE_SUFFIXES = ('.npy', '.csv')
BOUNDS_KEYS = ('min', 'max')
THREAT_KEYS = ('position', 'intensity', 'lethal_radius', 'velocity')
#: Fastest threat a scenario may give [m/s] (the cruise speed's upper bound).
MAX_THREAT_SPEED = 1000.0


def _velocity(i: int, value: object) -> list[float]:
    """Return threat `i`'s ``velocity`` [m/s], checked: three finite numbers, not too fast."""
    name = f'threats[{i}].velocity'
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or any(isinstance(v, bool) or not isinstance(v, numbers.Real) for v in value)):
        raise InputError(f'{name}: expected [vx, vy, vz] [m/s], got {value!r}')
    v = [float(x) for x in value]
    shown = '[' + ', '.join(f'{x:g}' for x in v) + ']'
    if not all(math.isfinite(x) for x in v):
        raise InputError(f'{name}: must be finite, got {shown}')
    speed = math.sqrt(sum(x * x for x in v))
    if speed > MAX_THREAT_SPEED:
        raise InputError(f'{name}: speed must be <= {MAX_THREAT_SPEED:g} [m/s], got {shown} '
                         f'(speed {speed:g})')
    return v


def _is_header(line: str) -> bool:
    """Whether a CSV first line is a header: no field of it reads as a number."""
    fields = [f.strip() for f in line.split('#')[0].split(',') if f.strip()]

    def number(text: str) -> bool:
        try:
            float(text)
        except ValueError:
            return False
        return True
    return bool(fields) and not any(number(f) for f in fields)


def read_threats_file(name: object, base: Path | None) -> np.ndarray:
    """Read a ``threats_file``: an (N, 4) array of x y z [m] and intensity F.

    Args:
        name: The field's value, a path relative to ``base`` (or absolute).
        base: Folder of the scenario file (None: the working directory).

    Returns:
        The rows, float, shape (N, 4).

    Raises:
        InputError: naming ``threats_file`` and what is wrong with it.
    """
    if not isinstance(name, str) or not name:
        raise InputError(f'threats_file: expected a file name, got {name!r}')
    path = Path(name) if base is None else base / name
    suffix = path.suffix.lower()
    if suffix not in THREATS_FILE_SUFFIXES:
        raise InputError(f'threats_file: {name} must end in '
                         f'{" or ".join(THREATS_FILE_SUFFIXES)}')
    try:
        if suffix == '.npy':
            rows = np.load(path, allow_pickle=False)
        else:
            with open(path, encoding='utf-8') as fh:
                header = _is_header(fh.readline())
                fh.seek(0)
                with warnings.catch_warnings():
                    # An empty table is a valid empty threat picture, not a warning.
                    warnings.simplefilter('ignore', UserWarning)
                    rows = np.loadtxt(fh, delimiter=',', comments='#', ndmin=2,
                                      skiprows=int(header))
    except OSError as exc:
        raise InputError(f'threats_file: cannot read {path} ({exc.strerror or exc})') from None
    except ValueError as exc:
        raise InputError(f'threats_file: {name} is not a table of numbers ({exc})') from None
    rows = np.asarray(rows)
    if rows.size == 0:
        return np.zeros((0, 4))
    if rows.ndim != 2 or rows.shape[1] != 4 or not np.issubdtype(rows.dtype, np.number):
        raise InputError(f'threats_file: {name} needs 4 numeric columns x y z F, got shape '
                         f'{list(rows.shape)}')
    return rows.astype(float)


def _threat_rows(data: dict, base: Path | None, fail) -> tuple:
    """Positions, intensities, lethal radii and velocities (``threats``/``threats_file``).

    The file gives arrays (already (N, 3) and (N,)) and no velocities (None); the YAML
    list gives lists, the velocities checked ((N, 3), zeros where a threat has none).
    """
    if 'threats_file' in data:
        if data.get('threats'):
            raise fail('give "threats" or "threats_file", not both')
        try:
            rows = read_threats_file(data['threats_file'], base)
        except InputError as exc:
            raise fail(str(exc)) from None
        return rows[:, :3], rows[:, 3], [float('nan')] * len(rows), None
    threats = data['threats'] if data['threats'] is not None else []
    if not isinstance(threats, list):
        raise fail('field "threats" must be a list')
    positions, intensities, lethal, velocities = [], [], [], []
    for i, t in enumerate(threats):
        if not isinstance(t, dict) or 'position' not in t or 'intensity' not in t:
            raise fail(f'threats[{i}] needs "position" and "intensity"')
        check_keys(t, THREAT_KEYS, f'threats[{i}].', fail)
        positions.append(t['position'])
        intensities.append(t['intensity'])
        lethal.append(t.get('lethal_radius', float('nan')))
        try:
            velocities.append(_velocity(i, t['velocity']) if 'velocity' in t else [0.0] * 3)
        except InputError as exc:
            raise fail(str(exc)) from None
    return positions, intensities, lethal, velocities


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
    for key in BLOCK_ONLY:
        if key in data:
            raise fail(f'unknown field "{key}"; it goes in the detection block: '
                       f'"detection.{key}"')
    check_keys(data, TOP_KEYS, '', fail)
    for key in ('bounds', 'start', 'goal'):
        if key not in data:
            raise fail(f'missing field "{key}"')
    if 'threats' not in data and 'threats_file' not in data:
        raise fail('missing field "threats" (or "threats_file")')
    bounds = data['bounds']
    if not isinstance(bounds, dict) or 'min' not in bounds or 'max' not in bounds:
        raise fail('field "bounds" needs "min" and "max"')
    check_keys(bounds, BOUNDS_KEYS, 'bounds.', fail)
    base = None if source.startswith('<') else Path(source).parent
    positions, intensities, lethal, velocities = _threat_rows(data, base, fail)
    try:
        datum, geodetic = frame_of(data)
        xyz = '[lat, lon, h]' if geodetic else '[x, y, z]'
        for i, p in enumerate(positions if isinstance(positions, list) else ()):
            if not isinstance(p, (list, tuple)) or len(p) != 3:
                raise InputError(f'threats[{i}].position: expected {xyz}, got {p!r}')
        air = {k: data[k] for k in ('no_fly_zones', 'terrain') if k in data}
        ends = data['start'], data['goal']
        if geodetic:
            local = to_local(data, positions, datum,
                             'threats_file' if 'threats_file' in data else 'threats')
            box, positions, ends = local['bounds'], local['positions'], (local['start'],
                                                                         local['goal'])
            if 'no_fly_zones' in air:
                air['no_fly_zones'] = local['no_fly_zones']
        else:
            box = Box.from_corners(bounds['min'], bounds['max'])
        if isinstance(air.get('terrain'), dict) and 'dem' in air['terrain']:
            air['terrain'] = dem_terrain(air['terrain'], datum, box, base)
        threat_field = ThreatField.from_arrays(
            np.array(positions, dtype=float).reshape(-1, 3), np.array(intensities, dtype=float))
        start, goal = check_endpoints(*ends, box, threat_field)
        airspace = Airspace.from_mapping(
            air, base, lethal_radii=[float('nan') if r is None else r for r in lethal],
            threat_positions=threat_field.positions)
        airspace.check_point('start', start)
        airspace.check_point('goal', goal)
        speed = speed_of(data)
        detection = detection_of(data)
    except InputError as exc:
        raise fail(str(exc)) from None
    except (TypeError, ValueError, OverflowError) as exc:
        raise fail(f'bad value ({exc})') from None
    return Scenario(str(data.get('name', Path(source).stem)), str(data.get('frame_id', 'map')),
                    str(data.get('description', '') or ''), box, start, goal, threat_field,
                    airspace, datum, speed, velocities, detection)


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
        data = load_document(text)
    except (yaml.YAMLError, ValueError, RecursionError) as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark else ''
        raise ScenarioError(f'{path}: not valid YAML{where}') from None
    return scenario_from_dict(data, str(path))


def save_scenario(scenario: Scenario, path: str | Path, threats_file: str | None = None) -> None:
    """Write a scenario file that :func:`load_scenario` reads back to the same scenario.

    Args:
        scenario: The scenario.
        path: The YAML file to write.
        threats_file: If given (``*.npy`` or ``*.csv``, relative to the YAML's folder), the
            threats go there as x y z F instead of the YAML list: for big pictures. Lethal
            radii need the list (the table has no column for them).

    Raises:
        InputError: a bad ``threats_file`` name, or lethal radii with a ``threats_file``.
    """
    path = Path(path)
    doc = scenario.to_dict()
    if threats_file is not None:
        suffix = Path(threats_file).suffix.lower()
        if suffix not in THREATS_FILE_SUFFIXES:
            raise InputError(f'threats_file: {threats_file} must end in '
                             f'{" or ".join(THREATS_FILE_SUFFIXES)}')
        if any('lethal_radius' in t for t in doc['threats']):
            raise InputError('threats_file: lethal radii need the threats list')
        if any('velocity' in t for t in doc['threats']):
            raise InputError('threats_file: threat velocities need the threats list')
        rows = np.column_stack([scenario.threats.positions, scenario.threats.intensities])
        table = path.parent / threats_file
        if suffix == '.npy':
            np.save(table, rows)
        else:
            # 17 significant digits: the floats read back bit for bit.
            np.savetxt(table, rows, delimiter=',', fmt='%.17g', header='x,y,z,F', comments='')
        doc.pop('threats')
        doc['threats_file'] = threats_file
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
