"""The WGS84 datum of a local frame and the conversions between geodetic and local ENU.

The local frame of a geodetic scenario is East-North-Up at the datum (lat0, lon0, h0): a
Cartesian frame, so every distance the planner measures in it is the true straight-line
distance. pymap3d does every conversion (through ECEF, vectorised); nothing here is
geodesy of its own. Heights are metres above the WGS84 ellipsoid (as NavSatFix's
altitude), not above the geoid.

What a flat frame cannot hold is a surface of constant height: the ENU level plane through
the datum rises above the ellipsoid with the distance d from the datum (about d^2 / 2R:
783 m at 100 km, 3,130 m at 200 km east of 45 N, computed by :func:`flattening_m`). A
flight box is a box of that frame, so its floor and ceiling are such planes; boxes wider
than :data:`MAX_SPAN_M` (measured with the datum in them) are refused.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.world.threats import Box
from threat_planner.errors import InputError

__all__ = ['Datum', 'MAX_SPAN_M', 'check_latlon', 'enu_box', 'flattening_m', 'geodetic_rows']

#: Widest geodetic box (east-west or north-south, the datum included) accepted [m].
MAX_SPAN_M = 200_000.0


def _plain(v: float) -> str:
    return f'{float(v):.10g}'


def check_latlon(name: str, lat: ArrayLike, lon: ArrayLike, rows: bool = False) -> None:
    """Raise InputError naming `name` (and the row) for a latitude or longitude out of range.

    Args:
        name: Field name, for example ``start`` or ``threats``.
        lat: Latitudes [deg], scalar or (N,).
        lon: Longitudes [deg], same shape.
        rows: Name the row (``threats[3]``) in the message.
    """
    lat, lon = np.atleast_1d(np.asarray(lat, float)), np.atleast_1d(np.asarray(lon, float))
    for what, values, limit in (('latitude', lat, 90.0), ('longitude', lon, 180.0)):
        bad = ~(np.abs(values) <= limit)
        if bad.any():
            i = int(np.argmax(bad))
            where = f'{name}[{i}]' if rows else name
            raise InputError(f'{where}: {what} {_plain(values[i])} outside '
                             f'[-{limit:g}, {limit:g}]')


def geodetic_rows(name: str, value: object, width: int = 3) -> NDArray:
    """Validate [lat, lon(, h)] rows: finite numbers, latitude and longitude in range.

    Args:
        name: Field name for errors.
        value: One row or a list of rows.
        width: 3 for [lat, lon, h], 2 for [lat, lon].

    Returns:
        Float array (N, width) (N = 1 for a single row).
    """
    what = '[lat, lon, h]' if width == 3 else '[lat, lon]'
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected {what}, got {value!r}') from None
    rows = arr.reshape(-1, width) if arr.size and arr.shape[-1:] == (width,) else None
    if rows is None or arr.ndim > 2:
        raise InputError(f'{name}: expected {what}, got {np.asarray(value).tolist()!r}')
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        where = f'{name}[{i}]' if arr.ndim == 2 else name
        raise InputError(f'{where}: not finite: {rows[i].tolist()}')
    check_latlon(name, rows[:, 0], rows[:, 1], rows=arr.ndim == 2)
    return rows


@dataclass(frozen=True)
class Datum:
    """Origin of a local ENU frame on WGS84.

    Attributes:
        lat_deg: Latitude [deg].
        lon_deg: Longitude [deg].
        h_m: Height above the WGS84 ellipsoid [m].
    """

    lat_deg: float
    lon_deg: float
    h_m: float

    @classmethod
    def parse(cls, value: object, name: str = 'datum') -> 'Datum':
        """Validate ``[lat, lon, h]``; errors name `name` and the bad number."""
        row = geodetic_rows(name, value)
        if len(row) != 1:
            raise InputError(f'{name}: expected [lat, lon, h], got {len(row)} rows')
        lat, lon, h = (float(v) for v in row[0])
        if abs(lat) == 90.0:
            # East and north are undefined at a pole.
            raise InputError(f'{name}: latitude {_plain(lat)} is a pole; the ENU frame '
                             'needs a datum off the poles')
        return cls(lat, lon, h)

    def as_list(self) -> list[float]:
        """``[lat, lon, h]``, as a scenario file writes it."""
        return [self.lat_deg, self.lon_deg, self.h_m]

    def to_enu(self, geodetic: ArrayLike) -> NDArray:
        """Local East, North, Up [m] of points (..., 3) given as lat [deg], lon [deg], h [m]."""
        import pymap3d
        g = np.asarray(geodetic, float)
        e, n, u = pymap3d.geodetic2enu(g[..., 0], g[..., 1], g[..., 2], self.lat_deg,
                                       self.lon_deg, self.h_m)
        return np.stack([np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)],
                        axis=-1)

    def to_geodetic(self, enu: ArrayLike) -> NDArray:
        """Lat [deg], lon [deg], h [m] of local ENU points (..., 3) [m]."""
        import pymap3d
        p = np.asarray(enu, float)
        lat, lon, h = pymap3d.enu2geodetic(p[..., 0], p[..., 1], p[..., 2], self.lat_deg,
                                           self.lon_deg, self.h_m)
        lon = (np.asarray(lon, float) + 180.0) % 360.0 - 180.0
        return np.stack([np.asarray(lat, float), lon, np.asarray(h, float)], axis=-1)


def flattening_m(datum: Datum, distance_m: float) -> float:
    """Height above the ellipsoid of the ENU level plane `distance_m` east of the datum [m].

    The error a flat frame makes in "height" at that distance: a path flying level in
    ENU there is this much higher above the ellipsoid than at the datum.
    """
    return float(datum.to_geodetic([distance_m, 0.0, 0.0])[2] - datum.h_m)


def enu_box(datum: Datum, lo_geo: object, hi_geo: object, name: str = 'bounds') -> Box:
    """Return the ENU box spanned by two geodetic corners (south-west-floor, north-east-ceiling).

    Each corner is converted as it is; the box runs from the first's east, north and up
    to the second's. The other corners of the latitude-longitude rectangle are not used
    (meridians converge: they lie slightly inside or outside the box).

    Args:
        datum: The frame's origin.
        lo_geo: ``[lat_south, lon_west, h_floor]``.
        hi_geo: ``[lat_north, lon_east, h_ceiling]``.
        name: Field name for errors (``bounds`` or ``no_fly_zones[i]``).

    Returns:
        The Box [m].

    Raises:
        InputError: a bad corner, corners in the wrong order, or a box wider than
            :data:`MAX_SPAN_M` together with the datum.
    """
    lo_g = geodetic_rows(f'{name}.min', lo_geo)[0]
    hi_g = geodetic_rows(f'{name}.max', hi_geo)[0]
    for k, (what, low, high) in enumerate((('latitude', 'south', 'north'),
                                           ('longitude', 'west', 'east'),
                                           ('height', 'floor', 'ceiling'))):
        if k != 1 and hi_g[k] <= lo_g[k]:
            raise InputError(f'{name}.max: {what} {_plain(hi_g[k])} ({high}) must exceed '
                             f'{name}.min {_plain(lo_g[k])} ({low})')
    lo, hi = datum.to_enu(np.stack([lo_g, hi_g]))
    span = np.maximum(hi[:2], 0.0) - np.minimum(lo[:2], 0.0)
    k = int(np.argmax(span))
    if span[k] > MAX_SPAN_M:
        raise InputError(
            f'{name}: the box spans {span[k] / 1e3:.1f} km {("east-west", "north-south")[k]} '
            f'(datum included), more than {MAX_SPAN_M / 1e3:g} km: the flat ENU frame '
            f'would put its level floor {flattening_m(datum, span[k]):.0f} m above the '
            f'ellipsoid height at the far side ({flattening_m(datum, MAX_SPAN_M):.0f} m at '
            f'{MAX_SPAN_M / 1e3:g} km); use a datum nearer the box or a smaller box')
    for k, (axis, word) in enumerate((('east', 'longitude'), ('north', 'latitude'),
                                      ('up', 'height'))):
        if hi[k] <= lo[k]:
            raise InputError(
                f'{name}.max: its {axis} coordinate {hi[k]:.3f} m does not exceed '
                f'{name}.min\'s {lo[k]:.3f} m in the ENU frame of the datum (check the '
                f'{word}s and their order: min is south-west-floor)')
    return Box.from_corners(lo, hi)
