"""``QGC WPL 110`` waypoint files, as ArduPilot, Mission Planner and QGroundControl load.

One line per item, tab-separated: index, current, frame, command, param1..4, latitude,
longitude, altitude, autocontinue. Item 0 is home (the start, frame 0 MAV_FRAME_GLOBAL,
its height above the ellipsoid); item 1 a MAV_CMD_DO_CHANGE_SPEED (178) to the plan's
cruise speed over the ground; then one MAV_CMD_NAV_WAYPOINT (16) per path point in
frame 3 (MAV_FRAME_GLOBAL_RELATIVE_ALT, altitude relative to home). Coordinates are
written with 9 decimals (0.1 mm), altitudes with 4 (0.1 mm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.geo.frames import Datum
from threat_planner.export.qgc import (MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_WAYPOINT,
                                       MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_MISSION,
                                       speed_params)

__all__ = ['HEADER', 'waypoints_text', 'write_waypoints']

HEADER = 'QGC WPL 110'
MAV_FRAME_GLOBAL = 0


def _line(i: int, frame: int, lat: float, lon: float, alt: float) -> str:
    fields = [str(i), '1' if i == 0 else '0', str(frame), str(MAV_CMD_NAV_WAYPOINT),
              '0', '0', '0', '0', f'{lat:.9f}', f'{lon:.9f}', f'{alt:.4f}', '1']
    return '\t'.join(fields)


def _speed_line(speed_m_s: float) -> str:
    params = [f'{v:g}' for v in speed_params(speed_m_s)]
    return '\t'.join(['1', '0', str(MAV_FRAME_MISSION), str(MAV_CMD_DO_CHANGE_SPEED), *params,
                      '0', '0', '0', '1'])


def waypoints_text(path: NDArray, datum: Datum, speed_m_s: float = 20.0) -> str:
    """Return the file's text: home (the path's first point), speed [m/s], every point."""
    geo = datum.to_geodetic(np.asarray(path, float))
    home = geo[0]
    lines = [HEADER, _line(0, MAV_FRAME_GLOBAL, *home), _speed_line(speed_m_s)]
    lines += [_line(i + 2, MAV_FRAME_GLOBAL_RELATIVE_ALT, lat, lon, h - home[2])
              for i, (lat, lon, h) in enumerate(geo)]
    return '\n'.join(lines) + '\n'


def write_waypoints(target: str | Path, path: NDArray, datum: Datum,
                    speed_m_s: float = 20.0) -> Path:
    """Write :func:`waypoints_text` to `target`; return the path."""
    target = Path(target)
    target.write_text(waypoints_text(path, datum, speed_m_s))
    return target
