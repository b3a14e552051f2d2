"""GeoJSON (RFC 7946) of a plan: the path, the threats, the start and goal, the zones.

A FeatureCollection of: the path as a LineString with heights ([lon, lat, h], heights
above the WGS84 ellipsoid [m]); each threat as a Point with its intensity F; the start
and goal as Points; each zone as a Polygon (its footprint, counter-clockwise, closed;
circles as 72-gons) with its kind and height range. Properties carry ``name`` and
``kind`` and the simplestyle keys (``stroke``, ``fill``, ``marker-color``) that
geojson.io, GitHub and QGIS's import show.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.geo.frames import Datum
from threat_planner.core.world.threats import ThreatField
from threat_planner.core.world.zones import Zone
from threat_planner.export.footprints import footprint

__all__ = ['feature_collection', 'write_geojson']


def _lonlat(geo: NDArray) -> list:
    """[lon, lat, h] rows: GeoJSON's axis order."""
    return [[float(r[1]), float(r[0]), *([float(r[2])] if len(r) > 2 else [])] for r in geo]


def _feature(geometry: dict, **properties: object) -> dict:
    return {'type': 'Feature', 'geometry': geometry, 'properties': properties}


def feature_collection(path: NDArray, datum: Datum, threats: Optional[ThreatField] = None,
                       zones: Iterable[Zone] = (), name: str = 'plan',
                       properties: Optional[dict] = None) -> dict:
    """Return the GeoJSON document of a plan.

    Args:
        path: Path points in the ENU frame of `datum` (n, 3) [m].
        datum: The frame's origin.
        threats: The threats, shown as Points with their intensity.
        zones: No-fly zones, shown as footprint Polygons.
        name: The path's name.
        properties: More properties of the path (J, feasibility, ...).

    Returns:
        The FeatureCollection (a dict).
    """
    geo = datum.to_geodetic(np.asarray(path, float))
    features = [_feature({'type': 'LineString', 'coordinates': _lonlat(geo)}, name=name,
                         kind='path', points=len(geo), stroke='#d62728',
                         **{'stroke-width': 3}, **(properties or {}))]
    for label, p in (('start', geo[0]), ('goal', geo[-1])):
        features.append(_feature({'type': 'Point', 'coordinates': _lonlat([p])[0]},
                                 name=label, kind=label, height_m=float(p[2]),
                                 **{'marker-color': '#2ca02c' if label == 'start'
                                    else '#1f77b4', 'marker-symbol': label[0]}))
    if threats is not None and len(threats):
        tg = datum.to_geodetic(threats.positions)
        for i, (p, f) in enumerate(zip(tg, threats.intensities)):
            features.append(_feature({'type': 'Point', 'coordinates': _lonlat([p])[0]},
                                     name=f'threat {i}', kind='threat',
                                     intensity=float(f), height_m=float(p[2]),
                                     **{'marker-color': '#ff7f0e',
                                        'marker-symbol': 'danger'}))
    for z in zones:
        fp = footprint(z, datum)
        ring = _lonlat(fp.polygon)
        ring.append(ring[0])
        features.append(_feature({'type': 'Polygon', 'coordinates': [ring]}, name=fp.label,
                                 kind=fp.kind, h_min_m=fp.h_min_m, h_max_m=fp.h_max_m,
                                 **({} if fp.radius_m is None else {'radius_m': fp.radius_m}),
                                 stroke='#7f7f7f', fill='#7f7f7f',
                                 **{'fill-opacity': 0.35}))
    return {'type': 'FeatureCollection', 'features': features}


def write_geojson(target: str | Path, path: NDArray, datum: Datum,
                  threats: Optional[ThreatField] = None, zones: Iterable[Zone] = (),
                  name: str = 'plan', properties: Optional[dict] = None) -> Path:
    """Write :func:`feature_collection` to `target`; return the path."""
    target = Path(target)
    doc = feature_collection(path, datum, threats, zones, name, properties)
    target.write_text(json.dumps(doc, indent=1, allow_nan=False) + '\n')
    return target
