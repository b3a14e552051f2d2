"""NavSatFix (sensor_msgs) in and out: GNSS fixes as points of the node's ENU frame.

A fix's latitude and longitude [deg] and altitude (metres above the WGS84 ellipsoid, as
the message defines it) become East, North, Up of parameter ``datum``
(:class:`~threat_planner.core.geo.frames.Datum`). A fix is refused with the reason when
its status is NO_FIX, when a number is NaN or out of range, or when the node has no datum.
The fix's own frame_id names the receiver, not the map, and is not checked.
"""

from __future__ import annotations

import math
from typing import Optional

from numpy.typing import NDArray
from sensor_msgs.msg import NavSatFix, NavSatStatus

from threat_planner.core.geo.frames import check_latlon, Datum
from threat_planner.errors import InputError

__all__ = ['navsatfix_from_geodetic', 'point_from_navsatfix']


def point_from_navsatfix(msg: NavSatFix, datum: Optional[Datum], name: str) -> NDArray:
    """Return the ENU point (3,) [m] of a fix.

    Args:
        msg: The fix.
        datum: The node's datum, or None.
        name: Input name for errors (``start_fix``, ``goal_fix``).

    Raises:
        InputError: the reason the fix cannot be used.
    """
    if datum is None:
        raise InputError(f'{name}: parameter datum is empty; a NavSatFix needs the WGS84 '
                         'origin [lat, lon, h] of frame_id')
    status = int(msg.status.status)
    if status == NavSatStatus.STATUS_NO_FIX:
        raise InputError(f'{name}: NavSatFix status is NO_FIX ({status}): the receiver '
                         'has no position')
    values = {'latitude': msg.latitude, 'longitude': msg.longitude,
              'altitude': msg.altitude}
    for field, v in values.items():
        if not math.isfinite(v):
            raise InputError(f'{name}: NavSatFix {field} is {v} (not a number): a start or '
                             'goal needs latitude, longitude and altitude')
    check_latlon(f'{name}.latitude/longitude', msg.latitude, msg.longitude)
    return datum.to_enu([msg.latitude, msg.longitude, msg.altitude])


def navsatfix_from_geodetic(lat: float, lon: float, h: float, stamp=None,
                            frame_id: str = 'gnss') -> NavSatFix:
    """Return a fix (status FIX, GPS) at latitude, longitude [deg] and height [m]."""
    msg = NavSatFix(latitude=float(lat), longitude=float(lon), altitude=float(h))
    msg.status.status = NavSatStatus.STATUS_FIX
    msg.status.service = NavSatStatus.SERVICE_GPS
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    return msg
