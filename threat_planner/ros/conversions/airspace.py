"""No-fly zones as visualization_msgs/MarkerArray and terrain as a sensor_msgs/Image.

Topic ``no_fly_zones`` (MarkerArray): one marker per zone, the whole zone set in one
message (it replaces the previous set, as a threat picture does). The marker's ``ns`` and
``id`` are the zone's label ``ns[id]`` (``no_fly_zones[3]``: ns ``no_fly_zones``, id 3):

* SPHERE: ``pose.position`` the centre, ``scale.x = scale.y = scale.z`` the diameter [m].
* CYLINDER: a vertical cylinder; ``pose.position`` the centre (z at mid-height),
  ``scale.x = scale.y`` the diameter, ``scale.z`` the height [m].
* CUBE: an axis-aligned box; ``pose.position`` the centre, ``scale`` its size [m].
* LINE_STRIP: a prism; ``points`` the simple polygon's vertices at z = z_min (a repeated
  first vertex closing the strip is dropped), ``scale.z`` the height [m] (``scale.x`` is
  RViz's line width). Point coordinates are offset by ``pose.position``.

Every zone marker's orientation must be the identity (zones are vertical or axis-aligned)
and its ``header.frame_id`` the node's frame. ``action`` DELETEALL drops the markers
before it in the array (an array holding only DELETEALL clears the zones); DELETE is
refused, since a message already is the whole set.

Topic ``terrain`` (Image): a ``32FC1`` height map [m], row r at y = y0 + r * resolution,
column c at x = x0 + c * resolution; origin, resolution, clearance and masking are the
node's ``terrain_*`` parameters. An image of zero width or height removes the terrain.
"""

from __future__ import annotations

import re
from typing import Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
import numpy as np
from numpy.typing import NDArray
from sensor_msgs.msg import Image
from visualization_msgs.msg import Marker, MarkerArray

from threat_planner.core.world.airspace import make_zone
from threat_planner.core.world.terrain import Terrain
from threat_planner.core.world.zones import BoxZone, Cylinder, Prism, Sphere, Zone
from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import check_frame, make_header

__all__ = ['ZONE_MARKER_TYPES', 'image_from_terrain', 'label_of_marker', 'marker_key',
           'terrain_from_image', 'zones_from_markers', 'zones_to_markers']

#: Zone kind -> marker type of topic ``no_fly_zones``.
ZONE_MARKER_TYPES = {'sphere': Marker.SPHERE, 'cylinder': Marker.CYLINDER,
                     'box': Marker.CUBE, 'prism': Marker.LINE_STRIP}
_KIND_OF_TYPE = {v: k for k, v in ZONE_MARKER_TYPES.items()}
_LABEL = re.compile(r'^(.*)\[(-?\d+)\](.*)$')
#: A quaternion within this of (0, 0, 0, +-1) counts as the identity.
_IDENTITY_TOL = 1e-9


def label_of_marker(ns: str, marker_id: int) -> str:
    """Return the zone label of a marker: ``ns[id]``."""
    return f'{ns}[{int(marker_id)}]'


def marker_key(label: str, index: int) -> tuple[str, int]:
    """Return the (ns, id) of a zone label; ``a[3].b`` -> (``a.b``, 3), else (label, index)."""
    m = _LABEL.match(label)
    if m is None:
        return label, int(index)
    return m.group(1) + m.group(3), int(m.group(2))


def _vec(v) -> list[float]:
    return [float(v.x), float(v.y), float(v.z)]


def _zone_from_marker(m: Marker, label: str) -> Zone:
    q = m.pose.orientation
    if (abs(q.x) > _IDENTITY_TOL or abs(q.y) > _IDENTITY_TOL or abs(q.z) > _IDENTITY_TOL
            or abs(abs(q.w) - 1.0) > _IDENTITY_TOL):
        raise InputError(f'{label}: orientation must be the identity, got '
                         f'[{float(q.x)}, {float(q.y)}, {float(q.z)}, {float(q.w)}]')
    c, size = _vec(m.pose.position), _vec(m.scale)
    kind = _KIND_OF_TYPE.get(m.type)
    if kind is None:
        raise InputError(f'{label}: marker type {int(m.type)} is not a zone (SPHERE 2, '
                         'CUBE 1, CYLINDER 3 or LINE_STRIP 4)')
    if kind == 'sphere':
        if not size[0] == size[1] == size[2]:
            raise InputError(f'{label}: a SPHERE needs scale.x = scale.y = scale.z, got '
                             f'{size}')
        return make_zone('sphere', label, center=c, radius=size[0] / 2)
    if kind == 'cylinder':
        if size[0] != size[1]:
            raise InputError(f'{label}: a CYLINDER needs scale.x = scale.y, got {size}')
        return make_zone('cylinder', label, center=c[:2], radius=size[0] / 2,
                         z_min=c[2] - size[2] / 2, z_max=c[2] + size[2] / 2)
    if kind == 'box':
        half = np.asarray(size) / 2
        return make_zone('box', label, min=np.asarray(c) - half, max=np.asarray(c) + half)
    pts = np.array([_vec(p) for p in m.points], float).reshape(-1, 3) + np.asarray(c)
    if len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]
    if len(pts) < 3:
        raise InputError(f'{label}: a LINE_STRIP prism needs at least 3 vertices, got '
                         f'{len(pts)}')
    if np.ptp(pts[:, 2]) != 0:
        raise InputError(f'{label}: a LINE_STRIP prism needs every point at one z (z_min), '
                         f'got {float(pts[:, 2].min())}..{float(pts[:, 2].max())}')
    z0 = float(pts[0, 2])
    return make_zone('prism', label, polygon=pts[:, :2], z_min=z0, z_max=z0 + size[2])


def zones_from_markers(msg: MarkerArray, expected_frame: str) -> tuple[Zone, ...]:
    """Read the zone set of a ``no_fly_zones`` MarkerArray (see the module docstring).

    Parameters
    ----------
    msg : visualization_msgs.msg.MarkerArray
        The zones.
    expected_frame : str
        The node's frame; every marker must be in it.

    Returns
    -------
    tuple of Zone
        The zones, labelled ``ns[id]``, in marker order.

    Raises
    ------
    InputError
        Naming the zone and the field: a wrong frame, type, orientation or scale, a
        duplicate ns/id, DELETE, or a zone the model refuses (negative radius, a polygon
        that is not simple).

    """
    zones: dict[str, Zone] = {}
    for m in msg.markers:
        if m.action == Marker.DELETEALL:
            zones.clear()
            continue
        label = label_of_marker(m.ns, m.id)
        if m.action == Marker.DELETE:
            raise InputError(f'{label}: action DELETE; a no_fly_zones message is the whole '
                             'zone set (leave the zone out, or DELETEALL to clear)')
        if m.action != Marker.ADD:
            raise InputError(f'{label}: unknown marker action {int(m.action)}')
        check_frame(f'no_fly_zones {label}', m.header.frame_id, expected_frame)
        if label in zones:
            raise InputError(f'{label}: duplicate marker ns/id')
        zones[label] = _zone_from_marker(m, label)
    return tuple(zones.values())


def zones_to_markers(zones: Sequence[Zone], frame_id: str, stamp: Time,
                     line_width: float = 1.0) -> MarkerArray:
    """Write zones as a ``no_fly_zones`` MarkerArray: DELETEALL, then one marker per zone.

    Parameters
    ----------
    zones : sequence of Zone
        The zones; labels become ns/id (:func:`marker_key`), ids made unique per ns.
    frame_id : str
        Frame of the markers.
    stamp : builtin_interfaces.msg.Time
        Their stamp.
    line_width : float, optional
        Line width of prism outlines [m].

    Returns
    -------
    visualization_msgs.msg.MarkerArray
        Read back by :func:`zones_from_markers` to the same zones.

    """
    header = make_header(frame_id, stamp)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    used: set[tuple[str, int]] = set()
    for i, z in enumerate(zones):
        ns, mid = marker_key(z.label, i)
        while (ns, mid) in used:
            mid += 1
        used.add((ns, mid))
        m = Marker(header=header, ns=ns, id=mid, type=ZONE_MARKER_TYPES[z.kind],
                   action=Marker.ADD)
        m.color.r, m.color.g, m.color.b, m.color.a = 0.9, 0.1, 0.1, 0.35
        m.pose.orientation.w = 1.0
        p, s = m.pose.position, m.scale
        if isinstance(z, Sphere):
            p.x, p.y, p.z = (float(v) for v in z.center)
            s.x = s.y = s.z = 2.0 * float(z.radius)
        elif isinstance(z, Cylinder):
            p.x, p.y = (float(v) for v in z.center)
            p.z = 0.5 * (z.z_min + z.z_max)
            s.x = s.y = 2.0 * float(z.radius)
            s.z = float(z.z_max - z.z_min)
        elif isinstance(z, BoxZone):
            p.x, p.y, p.z = (float(v) for v in 0.5 * (z.lo + z.hi))
            s.x, s.y, s.z = (float(v) for v in z.hi - z.lo)
        elif isinstance(z, Prism):
            ring = np.vstack([z.polygon, z.polygon[:1]])
            m.points = [Point(x=float(x), y=float(y), z=float(z.z_min)) for x, y in ring]
            s.x = float(line_width)
            s.z = float(z.z_max - z.z_min)
        markers.append(m)
    return MarkerArray(markers=markers)


def terrain_from_image(msg: Image, expected_frame: str, origin: NDArray, resolution: float,
                       clearance: float, masking: bool) -> Terrain | None:
    """Read a ``terrain`` 32FC1 height map; None for an empty image (no terrain).

    Raises
    ------
    InputError
        On another frame or encoding, a wrong step or data length, or heights the
        terrain model refuses (NaN, inf).

    """
    check_frame('terrain', msg.header.frame_id, expected_frame)
    rows, cols = int(msg.height), int(msg.width)
    if rows == 0 or cols == 0:
        return None
    if msg.encoding != '32FC1':
        raise InputError(f'terrain encoding must be 32FC1, got {msg.encoding!r}')
    step = int(msg.step)
    if step < 4 * cols or step % 4:
        raise InputError(f'terrain step must be a multiple of 4 and >= 4 * width = '
                         f'{4 * cols}, got {step}')
    data = bytes(msg.data)
    if len(data) != step * rows:
        raise InputError(f'terrain data has {len(data)} bytes, expected step * height = '
                         f'{step * rows}')
    grid = np.frombuffer(data, dtype='>f4' if msg.is_bigendian else '<f4')
    heights = grid.reshape(rows, step // 4)[:, :cols].astype(np.float64)
    return Terrain.from_arrays(origin, resolution, heights, clearance, masking)


def image_from_terrain(terrain: Terrain | None, frame_id: str, stamp: Time) -> Image:
    """Write a terrain's heights as a little-endian 32FC1 Image (empty for None)."""
    msg = Image(header=make_header(frame_id, stamp), encoding='32FC1', is_bigendian=0)
    if terrain is not None:
        h = np.ascontiguousarray(terrain.heights, dtype='<f4')
        msg.height, msg.width = (int(v) for v in h.shape)
        msg.step = 4 * msg.width
        msg.data = h.tobytes()
    return msg
