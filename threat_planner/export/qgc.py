"""QGroundControl plan files (``.plan``, fileType Plan, version 1).

The mission (version 2) has ``plannedHomePosition`` = the path's first point (the start),
a MAV_CMD_DO_CHANGE_SPEED (178) to the plan's cruise speed (ground speed: the times of the
plan's trajectory assume it), then one ``SimpleItem`` MAV_CMD_NAV_WAYPOINT (16) per path
point, in frame 3
(MAV_FRAME_GLOBAL_RELATIVE_ALT: altitude relative to home, here the start's height above
the ellipsoid; an autopilot flies the differences, whatever its home altitude). The
no-fly zones go in ``geoFence`` as exclusion circles (spheres at their widest, cylinders)
and exclusion polygons (boxes, prisms). QGroundControl and MAVSDK's
``import_qgroundcontrol_mission`` read the file (test/export checks the latter).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.geo.frames import Datum
from threat_planner.core.world.zones import Zone
from threat_planner.export.footprints import footprint

__all__ = ['MAV_CMD_DO_CHANGE_SPEED', 'MAV_CMD_NAV_WAYPOINT', 'MAV_FRAME_GLOBAL_RELATIVE_ALT',
           'MAV_FRAME_MISSION', 'qgc_plan', 'speed_params', 'write_qgc_plan']

MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
#: A command that is not a position: DO_CHANGE_SPEED's frame.
MAV_FRAME_MISSION = 2
#: DO_CHANGE_SPEED's speed type 1: ground speed (the plan's times are over the ground).
SPEED_TYPE_GROUND = 1
#: MAV_AUTOPILOT_GENERIC and MAV_TYPE_GENERIC: the plan names no particular vehicle.
FIRMWARE_GENERIC, VEHICLE_GENERIC = 0, 0


def speed_params(speed_m_s: float) -> list[float]:
    """Return DO_CHANGE_SPEED's params 1-4: ground speed, `speed_m_s`, throttle unchanged."""
    return [SPEED_TYPE_GROUND, float(speed_m_s), -1, 0]


def qgc_plan(path: NDArray, datum: Datum, zones: Iterable[Zone] = (),
             cruise_speed_m_s: float = 20.0, hover_speed_m_s: float = 5.0) -> dict:
    """Return the plan file's document.

    Args:
        path: Path points in the ENU frame of `datum` (n, 3) [m]; the first is home.
        datum: The frame's origin.
        zones: No-fly zones, as exclusion fences.
        cruise_speed_m_s: The plan's speed (setting ``speed_mps``) [m/s]: the mission's
            DO_CHANGE_SPEED and the speed QGroundControl estimates times with.
        hover_speed_m_s: The hover speed QGroundControl shows [m/s].

    Returns:
        The JSON document (a dict).
    """
    geo = datum.to_geodetic(np.asarray(path, float))
    home = geo[0]
    items = [{'type': 'SimpleItem', 'autoContinue': True, 'command': MAV_CMD_DO_CHANGE_SPEED,
              'doJumpId': 1, 'frame': MAV_FRAME_MISSION,
              'params': speed_params(cruise_speed_m_s) + [0, 0, 0]}]
    for i, (lat, lon, h) in enumerate(geo):
        alt = float(h - home[2])
        items.append({
            'type': 'SimpleItem', 'autoContinue': True, 'command': MAV_CMD_NAV_WAYPOINT,
            'doJumpId': i + 2, 'frame': MAV_FRAME_GLOBAL_RELATIVE_ALT,
            # hold [s], acceptance radius [m], pass radius [m], yaw (null: unchanged)
            'params': [0, 0, 0, None, float(lat), float(lon), alt],
            'Altitude': alt, 'AltitudeMode': 1, 'AMSLAltAboveTerrain': None})
    circles, polygons = [], []
    for z in zones:
        f = footprint(z, datum)
        if f.radius_m is not None:
            circles.append({'circle': {'center': f.center.tolist(), 'radius': f.radius_m},
                            'inclusion': False, 'version': 1})
        else:
            polygons.append({'polygon': f.polygon.tolist(), 'inclusion': False,
                             'version': 1})
    return {
        'fileType': 'Plan', 'version': 1, 'groundStation': 'threat_planner',
        'mission': {'version': 2, 'firmwareType': FIRMWARE_GENERIC,
                    'vehicleType': VEHICLE_GENERIC, 'cruiseSpeed': cruise_speed_m_s,
                    'hoverSpeed': hover_speed_m_s, 'items': items,
                    'plannedHomePosition': [float(v) for v in home]},
        'geoFence': {'version': 2, 'circles': circles, 'polygons': polygons},
        'rallyPoints': {'version': 2, 'points': []},
    }


def write_qgc_plan(target: str | Path, path: NDArray, datum: Datum,
                   zones: Iterable[Zone] = (), speed_m_s: float = 20.0) -> Path:
    """Write :func:`qgc_plan` to `target` (JSON, every float exact); return the path."""
    doc = qgc_plan(path, datum, zones, speed_m_s)
    target = Path(target)
    target.write_text(json.dumps(doc, indent=2, allow_nan=False) + '\n')
    return target
