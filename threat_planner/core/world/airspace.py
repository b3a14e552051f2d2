"""Airspace: the no-fly zones and the terrain of a problem, built from YAML or arrays.

The scenario keys (all optional)::

    no_fly_zones:
      - {type: sphere,   center: [x, y, z], radius: r}
      - {type: cylinder, center: [x, y], radius: r, z_min: a, z_max: b}
      - {type: box,      min: [x, y, z], max: [x, y, z]}
      - {type: prism,    polygon: [[x, y], ...], z_min: a, z_max: b}
    threats:
      - {position: [x, y, z], intensity: F, lethal_radius: r}   # a sphere zone
    terrain: {origin: [x0, y0], resolution: r, heights: [[...]] | file: dem.npy,
              clearance: c, masking: true}

Zones are open: a path may touch a boundary. Every point of every segment must stay
outside every zone and at least ``clearance`` above the terrain.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.world.terrain import Terrain
from threat_planner.core.world.zones import (BoxZone, Cylinder, polygon_is_simple, Prism, Sphere,
                                             Zone)
from threat_planner.errors import InputError

__all__ = ['Airspace', 'Clearance', 'zone_from_mapping', 'terrain_from_mapping']

_ZONE_KEYS = {'sphere': {'type', 'center', 'radius'},
              'cylinder': {'type', 'center', 'radius', 'z_min', 'z_max'},
              'box': {'type', 'min', 'max'},
              'prism': {'type', 'polygon', 'z_min', 'z_max'}}
_TERRAIN_KEYS = {'origin', 'resolution', 'heights', 'file', 'clearance', 'masking'}


def _vector(name: str, value: object, n: int) -> NDArray:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected {n} numbers, got {value!r}') from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise InputError(f'{name}: expected {n} finite numbers, got {arr.tolist()}')
    return arr


def _number(name: str, value: object, positive: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected a number, got {value!r}') from None
    if not np.isfinite(v):
        raise InputError(f'{name}: not finite, got {v}')
    if positive and v <= 0:
        raise InputError(f'{name}: must be positive, got {v}')
    return v


def _slab(name: str, z_min: float, z_max: float) -> None:
    if z_max <= z_min:
        raise InputError(f'{name}.z_max: must exceed z_min ({z_min}), got {z_max}')


def make_zone(kind: str, name: str = 'zone', **kw: object) -> Zone:
    """Validate and build one zone from arrays (the keys of the YAML model)."""
    if kind == 'sphere':
        return Sphere(_vector(f'{name}.center', kw['center'], 3),
                      _number(f'{name}.radius', kw['radius'], True), name)
    if kind == 'cylinder':
        z0, z1 = _number(f'{name}.z_min', kw['z_min']), _number(f'{name}.z_max', kw['z_max'])
        _slab(name, z0, z1)
        return Cylinder(_vector(f'{name}.center', kw['center'], 2),
                        _number(f'{name}.radius', kw['radius'], True), z0, z1, name)
    if kind == 'box':
        lo, hi = _vector(f'{name}.min', kw['min'], 3), _vector(f'{name}.max', kw['max'], 3)
        if np.any(hi <= lo):
            k = int(np.argmax(hi <= lo))
            raise InputError(f'{name}.max: max.{"xyz"[k]} must exceed min.{"xyz"[k]} '
                             f'({float(lo[k])}), got {float(hi[k])}')
        return BoxZone(lo, hi, name)
    if kind == 'prism':
        z0, z1 = _number(f'{name}.z_min', kw['z_min']), _number(f'{name}.z_max', kw['z_max'])
        _slab(name, z0, z1)
        try:
            poly = np.asarray(kw['polygon'], float)
        except (TypeError, ValueError):
            raise InputError(f'{name}.polygon: expected [[x, y], ...], got '
                             f'{kw["polygon"]!r}') from None
        if poly.ndim != 2 or poly.shape[1] != 2 or not np.all(np.isfinite(poly)):
            raise InputError(f'{name}.polygon: expected finite [[x, y], ...], got shape '
                             f'{list(poly.shape)}')
        simple, why = polygon_is_simple(poly)
        if not simple:
            raise InputError(f'{name}.polygon: not a simple polygon ({why})')
        return Prism(poly, z0, z1, name)
    raise InputError(f'{name}.type: expected sphere, cylinder, box or prism, got {kind!r}')


def zone_from_mapping(data: object, name: str) -> Zone:
    """One ``no_fly_zones`` entry of the YAML model; errors name ``name`` and the key."""
    if not isinstance(data, dict) or 'type' not in data:
        raise InputError(f'{name}: expected a mapping with "type"')
    kind = data['type']
    if kind not in _ZONE_KEYS:
        raise InputError(f'{name}.type: expected sphere, cylinder, box or prism, '
                         f'got {kind!r}')
    unknown = sorted(set(map(str, data)) - _ZONE_KEYS[kind])
    if unknown:
        raise InputError(f'{name}.{unknown[0]}: unknown key for a {kind}')
    missing = sorted(_ZONE_KEYS[kind] - set(data))
    if missing:
        raise InputError(f'{name}.{missing[0]}: missing')
    return make_zone(kind, name, **{k: v for k, v in data.items() if k != 'type'})


def terrain_from_mapping(data: object, base: Optional[Path] = None) -> Terrain:
    """Build the ``terrain`` mapping of the YAML model; ``file`` is relative to ``base``."""
    if not isinstance(data, dict):
        raise InputError('terrain: expected a mapping')
    unknown = sorted(set(map(str, data)) - _TERRAIN_KEYS)
    if unknown:
        raise InputError(f'terrain.{unknown[0]}: unknown key')
    for key in ('origin', 'resolution'):
        if key not in data:
            raise InputError(f'terrain.{key}: missing')
    if ('heights' in data) == ('file' in data):
        raise InputError('terrain: give exactly one of "heights" and "file"')
    if 'file' in data:
        path = Path(str(data['file']))
        path = path if path.is_absolute() or base is None else base / path
        try:
            heights = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f'terrain.file: cannot read {path} ({exc})') from None
    else:
        heights = data['heights']
    return Terrain.from_arrays(data['origin'], _number('terrain.resolution',
                                                       data['resolution']),
                               heights, data.get('clearance', 0.0),
                               data.get('masking', False))


@dataclass(frozen=True)
class Clearance:
    """Smallest margins of a path: to every zone and above terrain + clearance [m].

    Attributes:
        zones_m: Smallest distance to any zone (inf without zones) [m].
        terrain_m: Smallest height above terrain minus the clearance (inf without) [m].
        per_zone: Zone label -> smallest distance of the path to it [m].
    """

    zones_m: float
    terrain_m: float
    per_zone: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """JSON layout: ``{zones_m, terrain_m, per_zone}`` (null for infinite)."""
        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None
        return {'zones_m': num(self.zones_m), 'terrain_m': num(self.terrain_m),
                'per_zone': {k: num(v) for k, v in self.per_zone.items()}}


@dataclass(frozen=True)
class Airspace:
    """No-fly zones and terrain.

    Attributes:
        zones: The zones, each labelled (``no_fly_zones[i]`` or ``threats[i].lethal_radius``).
        terrain: The terrain, or None.
    """

    zones: tuple[Zone, ...] = ()
    terrain: Optional[Terrain] = None

    @classmethod
    def from_mapping(cls, data: object, base: Optional[Path] = None,
                     lethal_radii: Optional[ArrayLike] = None,
                     threat_positions: Optional[ArrayLike] = None) -> 'Airspace':
        """Build from the YAML keys ``no_fly_zones`` and ``terrain`` (and lethal radii).

        Args:
            data: Mapping holding any of ``no_fly_zones`` and ``terrain``.
            base: Folder a terrain ``file`` is relative to.
            lethal_radii: One per threat, NaN for none [m].
            threat_positions: Threat positions (N, 3) [m], for the lethal radii.
        """
        data = {} if data is None else data
        if not isinstance(data, dict):
            raise InputError('airspace: expected a mapping')
        raw = data.get('no_fly_zones') or []
        if not isinstance(raw, list):
            raise InputError('no_fly_zones: expected a list')
        zones = [zone_from_mapping(z, f'no_fly_zones[{i}]') for i, z in enumerate(raw)]
        zones += lethal_zones(threat_positions, lethal_radii)
        terrain = (terrain_from_mapping(data['terrain'], base)
                   if data.get('terrain') is not None else None)
        return cls(tuple(zones), terrain)

    def lethal_radii(self, n_threats: int) -> NDArray:
        """Lethal radius of each threat [m], NaN where it has none."""
        out = np.full(n_threats, np.nan)
        for z in self.zones:
            if z.label.startswith('threats['):
                out[int(z.label[8:z.label.index(']')])] = z.radius
        return out

    def to_mapping(self) -> dict:
        """Return the ``no_fly_zones`` and ``terrain`` keys (lethal radii stay with threats)."""
        out: dict = {}
        zones = [z for z in self.zones if not z.label.startswith('threats[')]
        if zones:
            out['no_fly_zones'] = [zone_to_mapping(z) for z in zones]
        t = self.terrain
        if t is not None:
            out['terrain'] = {'origin': t.origin.tolist(), 'resolution': t.resolution,
                              'heights': t.heights.tolist(), 'clearance': t.clearance,
                              'masking': t.masking}
        return out

    def __bool__(self) -> bool:
        """Return whether there is anything to respect."""
        return bool(self.zones) or self.terrain is not None

    @property
    def masking(self) -> bool:
        """Whether the terrain hides the UAV from radars."""
        return self.terrain is not None and self.terrain.masking

    def check_point(self, name: str, p: NDArray) -> None:
        """Refuse a start or goal inside a zone or below the terrain floor."""
        p = np.asarray(p, float)
        for z in self.zones:
            d = float(z.sdf(p[None])[0])
            if d < 0:
                raise InputError(f'{name}: {p.tolist()} is inside {z.label} ({z.kind}, '
                                 f'{-d:.6g} m deep)')
        if self.terrain is not None:
            above = float(p[2] - self.terrain.height(p[None, :2])[0])
            if above < self.terrain.clearance - 1e-9:
                raise InputError(f'{name}: {p.tolist()} is {above:.6g} m above the terrain, '
                                 f'below terrain.clearance {self.terrain.clearance:g}')

    def zone_margins(self, a: NDArray, b: NDArray) -> NDArray:
        """Smallest signed distance of each segment to each zone, (Z, S) [m]."""
        a, b = np.atleast_2d(a), np.atleast_2d(b)
        if not self.zones:
            return np.zeros((0, len(a)))
        return np.stack([z.segment_distance(a, b)[0] for z in self.zones])

    def terrain_margins(self, a: NDArray, b: NDArray) -> NDArray:
        """Height above terrain minus clearance, smallest along each segment (S,) [m]."""
        if self.terrain is None:
            return np.full(len(np.atleast_2d(a)), np.inf)
        return self.terrain.clearance_margin(a, b)

    def segment_ok(self, a: NDArray, b: NDArray, tol: float = 1e-9) -> NDArray:
        """Whether each segment stays outside every zone and above the floor (S,)."""
        a, b = np.atleast_2d(a), np.atleast_2d(b)
        ok = self.terrain_margins(a, b) >= -tol
        for z in self.zones:
            # A prism's exact crossing test decides alone (open interior) and is cheaper.
            ok &= (~z.crosses(a, b) if isinstance(z, Prism)
                   else z.segment_distance(a, b)[0] >= -tol)
        return ok

    def clearance(self, points: NDArray) -> Clearance:
        """Smallest margins of a polyline (n, 3) to the zones and the terrain floor."""
        points = np.asarray(points, float)
        a, b = points[:-1], points[1:]
        per = {}
        for z, m in zip(self.zones, self.zone_margins(a, b)):
            per[z.label] = float(m.min(initial=np.inf))
        zmin = min(per.values(), default=float('inf'))
        return Clearance(zmin, float(self.terrain_margins(a, b).min(initial=np.inf)), per)

    def violations(self, points: NDArray, tol: float = 1e-9) -> list[tuple[str, float]]:
        """(zone label or 'terrain', depth [m]) of every constraint a polyline breaks."""
        c = self.clearance(points)
        out = [(k, -v) for k, v in c.per_zone.items() if v < -tol]
        prisms = [z for z in self.zones if isinstance(z, Prism)]
        pts = np.asarray(points, float)
        for z in prisms:
            if c.per_zone[z.label] >= -tol and z.crosses(pts[:-1], pts[1:]).any():
                out.append((z.label, 0.0))
        if c.terrain_m < -tol:
            out.append(('terrain', -c.terrain_m))
        return sorted(out, key=lambda item: -item[1])


def zone_to_mapping(z: Zone) -> dict:
    """One zone in the YAML model's layout."""
    if isinstance(z, Sphere):
        return {'type': 'sphere', 'center': z.center.tolist(), 'radius': z.radius}
    if isinstance(z, Cylinder):
        return {'type': 'cylinder', 'center': z.center.tolist(), 'radius': z.radius,
                'z_min': z.z_min, 'z_max': z.z_max}
    if isinstance(z, BoxZone):
        return {'type': 'box', 'min': z.lo.tolist(), 'max': z.hi.tolist()}
    return {'type': 'prism', 'polygon': z.polygon.tolist(), 'z_min': z.z_min,
            'z_max': z.z_max}


def lethal_zones(positions: Optional[ArrayLike], radii: Optional[ArrayLike]) -> list[Zone]:
    """Sphere zones ``threats[i].lethal_radius`` around threats with a radius (not NaN)."""
    if radii is None or positions is None:
        return []
    radii = np.asarray(radii, float).reshape(-1)
    pos = np.asarray(positions, float).reshape(-1, 3)
    out = []
    for i, r in enumerate(radii):
        if np.isnan(r):
            continue
        _number(f'threats[{i}].lethal_radius', r, positive=True)
        out.append(make_zone('sphere', f'threats[{i}].lethal_radius', center=pos[i],
                             radius=r))
    return out
