"""Scenario keys in WGS84: ``datum``, ``coordinates: geodetic`` and ``terrain: {dem: ...}``.

A geodetic scenario gives every position as latitude [deg], longitude [deg] and height
above the WGS84 ellipsoid [m], in the same places a local one gives x, y, z:

* ``start``, ``goal``, threat ``position`` and sphere ``center``: ``[lat, lon, h]``;
* ``bounds`` and box zones: ``min: [lat_south, lon_west, h_floor]``, ``max: [lat_north,
  lon_east, h_ceiling]``; the box is the ENU box spanned by those two corners
  (:func:`~threat_planner.core.geo.frames.enu_box`);
* cylinder ``center``: ``[lat, lon]`` and prism ``polygon``: ``[[lat, lon], ...]``, with
  ``z_min`` / ``z_max`` heights above the ellipsoid [m]; the zone stands vertical in the
  ENU frame, its outline taken at mid-height and its heights at its centre;
* ``threats_file`` columns lat, lon, h, F.

Sizes (radius, lethal_radius, clearance) stay metres. Everything is converted once to the
ENU frame of ``datum`` here, and the scenario is then read as a local one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
from threat_planner.core.geo.frames import check_latlon, Datum, enu_box, geodetic_rows
from threat_planner.core.world.threats import Box
from threat_planner.errors import InputError

__all__ = ['COORDINATES', 'DEM_KEYS', 'dem_terrain', 'frame_of', 'to_local']

COORDINATES = ('local', 'geodetic')
#: Keys of a ``terrain`` mapping that reads a DEM.
DEM_KEYS = ('dem', 'clearance', 'masking', 'resolution', 'height_offset')


def frame_of(data: dict) -> tuple[Optional[Datum], bool]:
    """Return the scenario's datum (or None) and whether its coordinates are geodetic."""
    coordinates = data.get('coordinates', 'local')
    if coordinates not in COORDINATES:
        raise InputError(f'coordinates: expected local or geodetic, got {coordinates!r}')
    datum = Datum.parse(data['datum']) if data.get('datum') is not None else None
    if coordinates == 'geodetic' and datum is None:
        raise InputError('coordinates: geodetic needs a "datum: [lat, lon, h]" (the origin '
                         'of the local ENU frame)')
    return datum, coordinates == 'geodetic'


def _point(datum: Datum, name: str, value: object) -> list[float]:
    return datum.to_enu(geodetic_rows(name, value)[0]).tolist()


def _number(value: object) -> Optional[float]:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) else None


def _zone(datum: Datum, z: object, name: str) -> object:
    """One geodetic zone mapping in ENU; malformed ones go on for the zone reader to name."""
    if not isinstance(z, dict):
        return z
    out, kind = dict(z), z.get('type')
    z0, z1 = _number(z.get('z_min')), _number(z.get('z_max'))
    mid = 0.0 if z0 is None or z1 is None else 0.5 * (z0 + z1)
    if kind == 'sphere' and 'center' in z:
        out['center'] = _point(datum, f'{name}.center', z['center'])
    elif kind == 'box' and 'min' in z and 'max' in z:
        box = enu_box(datum, z['min'], z['max'], name)
        out['min'], out['max'] = box.lo.tolist(), box.hi.tolist()
    elif kind in ('cylinder', 'prism'):
        key = 'center' if kind == 'cylinder' else 'polygon'
        if key not in z:
            return out
        rows = geodetic_rows(f'{name}.{key}', z[key], width=2)
        at = lambda h: np.column_stack([rows, np.full(len(rows), h)])  # noqa: E731
        xy = datum.to_enu(at(mid))[:, :2]
        out[key] = xy[0].tolist() if kind == 'cylinder' else xy.tolist()
        centre = rows.mean(axis=0)
        for k, h in (('z_min', z0), ('z_max', z1)):
            if h is not None:
                out[k] = float(datum.to_enu([centre[0], centre[1], h])[2])
    return out


def to_local(data: dict, positions: object, datum: Datum, threats_name: str) -> dict:
    """Return the geodetic keys of a scenario in the ENU frame of `datum`.

    Args:
        data: The scenario mapping (``coordinates: geodetic``).
        positions: Threat positions as read, (N, 3) lat, lon, h.
        datum: The frame's origin.
        threats_name: ``threats`` or ``threats_file``, for errors.

    Returns:
        ``{'bounds': Box, 'start', 'goal', 'positions' (N, 3), 'no_fly_zones'}`` [m].

    Raises:
        InputError: naming the field: a latitude or longitude out of range, a bad corner
            order, a box wider than the limit.
    """
    bounds = data['bounds']
    box = enu_box(datum, bounds['min'], bounds['max'])
    pos = np.asarray(positions, dtype=float).reshape(-1, 3)
    if len(pos):
        bad = ~np.isfinite(pos).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f'{threats_name}[{i}]: not finite: {pos[i].tolist()}')
        check_latlon(threats_name, pos[:, 0], pos[:, 1], rows=True)
        pos = datum.to_enu(pos)
    zones = data.get('no_fly_zones')
    if isinstance(zones, list):
        zones = [_zone(datum, z, f'no_fly_zones[{i}]') for i, z in enumerate(zones)]
    return {'bounds': box, 'start': _point(datum, 'start', data['start']),
            'goal': _point(datum, 'goal', data['goal']), 'positions': pos,
            'no_fly_zones': zones}


def dem_terrain(terrain: dict, datum: Optional[Datum], box: Box, base: Optional[Path]
                ) -> dict:
    """Turn a ``terrain: {dem: FILE.tif, ...}`` mapping into the grid the airspace reads.

    Raises:
        InputError: naming ``terrain`` and the key: no datum, an unknown key or one of the
            grid form, or what :func:`~threat_planner.core.geo.dem.dem_grid` refuses.
    """
    for key in terrain:
        if key not in DEM_KEYS:
            raise InputError(f'terrain.{key}: not a key of a DEM terrain (known: '
                             f'{", ".join(DEM_KEYS)})')
    if datum is None:
        raise InputError('terrain.dem: a DEM needs the scenario\'s "datum: [lat, lon, h]"')
    from threat_planner.core.geo.dem import dem_grid
    name = terrain['dem']
    if not isinstance(name, str) or not name:
        raise InputError(f'terrain.dem: expected a file name, got {name!r}')
    path = Path(name)
    path = path if path.is_absolute() or base is None else base / path
    resolution = terrain.get('resolution')
    if resolution is not None and not (_number(resolution) or 0.0) > 0:
        raise InputError(f'terrain.resolution: must be a positive number, got {resolution!r}')
    offset = _number(terrain.get('height_offset', 0.0))
    if offset is None:
        raise InputError(f'terrain.height_offset: expected a number, got '
                         f'{terrain["height_offset"]!r}')
    origin, res, heights = dem_grid(path, datum, box, None if resolution is None
                                    else float(resolution), offset, name)
    out = {'origin': origin.tolist(), 'resolution': res, 'heights': heights}
    out.update({k: terrain[k] for k in ('clearance', 'masking') if k in terrain})
    return out
