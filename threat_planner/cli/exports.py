"""The exports of ``threat-planner plan``.

``--qgc``, ``--waypoints``, ``--geojson``, ``--max-waypoints`` and the ``path_geodetic`` of
``--json``.

Heavy work is done only when asked: a plan without these options imports nothing here
but argparse's definitions.
"""

from __future__ import annotations

import argparse
from typing import Optional

from threat_planner.cli.options import output_file
from threat_planner.errors import InputError

__all__ = ['add_export_options', 'check_exports', 'export_plan']

_FILES = ('qgc', 'waypoints', 'geojson')


def add_export_options(parser: argparse.ArgumentParser) -> None:
    """Add the export options to the ``plan`` verb."""
    group = parser.add_argument_group(
        'exports', 'mission and map files of the plan (the scenario needs a datum)')
    group.add_argument('--qgc', metavar='OUT.plan',
                       help='write a QGroundControl plan: waypoints (altitude relative to '
                            'the start) and the no-fly zones as exclusion fences')
    group.add_argument('--waypoints', metavar='OUT.waypoints',
                       help='write a QGC WPL 110 waypoint file (ArduPilot, Mission Planner)')
    group.add_argument('--geojson', metavar='OUT.geojson',
                       help='write GeoJSON: path, threats, start, goal, zone footprints')
    group.add_argument('--max-waypoints', metavar='N', type=int,
                       help='thin the exported path to at most N points where it keeps '
                            'the flight limits and zone clearances; prints its J')


def check_exports(args: argparse.Namespace, scenario) -> None:
    """Refuse export options the scenario cannot serve, before planning."""
    asked = [f'--{k}' for k in _FILES if getattr(args, k, None)]
    if asked and scenario.datum is None:
        raise InputError(f'{asked[0]}: the scenario has no datum; add "datum: [lat, lon, h]" '
                         '(the WGS84 origin of its frame)')
    n = getattr(args, 'max_waypoints', None)
    if n is not None and n < 2:
        raise InputError(f'max_waypoints: must be >= 2 (start and goal), got {n}')


def export_plan(args: argparse.Namespace, scenario, result, config,
                summary: Optional[dict] = None) -> list[str]:
    """Write the asked-for files; add ``path_geodetic`` (and ``exported``) to `summary`.

    Returns:
        Lines for the command's report.
    """
    datum = scenario.datum
    path, lines = result.path, []
    if args.max_waypoints is not None:
        from threat_planner.export.thin import thin_path
        thinned = thin_path(result.path, args.max_waypoints, scenario.threats, scenario.box,
                            config, scenario.airspace or None)
        path, c = thinned.points, thinned.cost
        lines.append(f'  exported: {len(path)} of {len(result.path)} points, J={c.J:.3f} '
                     f'J_L={c.J_L:.3f} J_R={c.J_R:.3f} (plan J={result.cost.J:.3f})')
        if summary is not None:
            summary['exported'] = {'points': len(path), 'kept': thinned.kept.tolist(),
                                   'path': path.tolist(), 'cost': c.as_dict()}
    if datum is None:
        return lines
    if summary is not None:
        summary['datum'] = datum.as_list()
        summary['path_geodetic'] = datum.to_geodetic(result.path).tolist()
        if 'exported' in summary:
            summary['exported']['path_geodetic'] = datum.to_geodetic(path).tolist()
    zones = scenario.airspace.zones
    if args.qgc:
        from threat_planner.export.qgc import write_qgc_plan
        out = write_qgc_plan(output_file(args.qgc), path, datum, zones,
                             config.speed_mps)
        lines.append(f'  QGroundControl plan: {out}')
    if args.waypoints:
        from threat_planner.export.waypoints import write_waypoints
        out = write_waypoints(output_file(args.waypoints), path, datum, config.speed_mps)
        lines.append(f'  waypoints: {out}')
    if args.geojson:
        from threat_planner.export.geojson import write_geojson
        props = {'J': float(result.cost.J) if args.max_waypoints is None else float(c.J),
                 'feasible': bool(result.feasible), 'method': config.method}
        out = write_geojson(output_file(args.geojson), path, datum, scenario.threats, zones,
                            scenario.name, props)
        lines.append(f'  GeoJSON: {out}')
    return lines
