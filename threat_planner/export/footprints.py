"""Zones as a map sees them: circles and polygons in latitude and longitude.

A fence of QGroundControl or ArduPilot is a ground outline: a sphere becomes the circle
of its widest section, a cylinder its disc, a box its rectangle and a prism its polygon.
Outlines are converted at the zone's mid-height (the ENU vertical leans from the local
one away from the datum, by the distance over the earth's radius), heights at its centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.geo.frames import Datum
from threat_planner.core.world.zones import BoxZone, Cylinder, Prism, Sphere, Zone

__all__ = ['Footprint', 'footprint']

#: Vertices of the polygon standing for a circle in GeoJSON.
CIRCLE_VERTICES = 72


@dataclass(frozen=True)
class Footprint:
    """A zone's outline on WGS84.

    Attributes:
        label: The zone's label (``no_fly_zones[2]``).
        kind: sphere, cylinder, box or prism.
        center: Latitude, longitude of the centre [deg] (2,).
        radius_m: Circle radius [m], or None for a polygon.
        polygon: Outline [[lat, lon], ...] counter-clockwise seen from above, not closed.
        h_min_m, h_max_m: Lowest and highest height above the ellipsoid at the centre [m].
    """

    label: str
    kind: str
    center: NDArray
    radius_m: float | None
    polygon: NDArray
    h_min_m: float
    h_max_m: float


def _ccw(xy: NDArray) -> NDArray:
    area = np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
    return xy if area > 0 else xy[::-1]


def footprint(zone: Zone, datum: Datum) -> Footprint:
    """Return the outline of one zone (ENU, in the frame of `datum`) in latitude and longitude."""
    if isinstance(zone, Sphere):
        c, r = zone.center, zone.radius
        z0, z1, ring, radius = c[2] - r, c[2] + r, None, r
    elif isinstance(zone, Cylinder):
        c = np.array([*zone.center, 0.5 * (zone.z_min + zone.z_max)])
        z0, z1, ring, radius = zone.z_min, zone.z_max, None, zone.radius
    elif isinstance(zone, BoxZone):
        lo, hi = zone.lo, zone.hi
        ring = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        c, z0, z1, radius = 0.5 * (lo + hi), lo[2], hi[2], None
    elif isinstance(zone, Prism):
        ring = _ccw(np.asarray(zone.polygon, float))
        c = np.array([*ring.mean(axis=0), 0.5 * (zone.z_min + zone.z_max)])
        z0, z1, radius = zone.z_min, zone.z_max, None
    else:   # pragma: no cover - every zone type is above
        raise TypeError(f'no footprint for {type(zone).__name__}')
    if ring is None:
        a = np.linspace(0.0, 2 * np.pi, CIRCLE_VERTICES, endpoint=False)
        ring = c[:2] + radius * np.column_stack([np.cos(a), np.sin(a)])
    geo = datum.to_geodetic(np.column_stack([ring, np.full(len(ring), c[2])]))
    centre = datum.to_geodetic(np.array([[c[0], c[1], z0], [c[0], c[1], z1],
                                         [c[0], c[1], c[2]]]))
    return Footprint(zone.label, zone.kind, centre[2, :2], None if radius is None
                     else float(radius), geo[:, :2], float(centre[0, 2]), float(centre[1, 2]))
