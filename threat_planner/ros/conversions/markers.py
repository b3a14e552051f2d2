"""The plan drawn as visualization_msgs/MarkerArray for RViz and Foxglove."""

from typing import Optional

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
import numpy as np
from numpy.typing import ArrayLike, NDArray
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import (as_edges, as_points, check_finite_rows,
                                                    make_header)
from threat_planner.ros.conversions.airspace import zones_to_markers

#: Above this many threats, :func:`network_markers` draws one fixed-size SPHERE_LIST
#: instead of one intensity-scaled SPHERE per threat (RViz cost grows per marker).
SPHERES_PER_THREAT_MAX = 500


def _to_point_msgs(points: NDArray[np.float64]) -> list[Point]:
    return [Point(x=x, y=y, z=z) for x, y, z in points.tolist()]


def _rgba(r: float, g: float, b: float, a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=r, g=g, b=b, a=a)


def _marker(ns: str, marker_id: int, marker_type: int, header: Header, scale: float,
            color: ColorRGBA) -> Marker:
    marker = Marker(header=header, ns=ns, id=marker_id, type=marker_type,
                    action=Marker.ADD, color=color)
    marker.scale.x = marker.scale.y = marker.scale.z = float(scale)
    return marker


def _threat_colors(weights: NDArray[np.float64]) -> list[ColorRGBA]:
    """Yellow for the weakest threat to red for the strongest."""
    return [_rgba(1.0, 1.0 - w, 0.0, 0.8) for w in weights.tolist()]


def network_markers(
    threat_positions: ArrayLike,
    intensities: ArrayLike,
    *,
    vertices: ArrayLike,
    delaunay_edges: ArrayLike,
    nodes: ArrayLike,
    network_edges: ArrayLike,
    initial_path: Optional[ArrayLike],
    path: Optional[ArrayLike],
    frame_id: str,
    stamp: Time,
    threat_diameter: float = 4.0,
    node_diameter: float = 1.0,
    line_width: float = 0.2,
) -> MarkerArray:
    """
    Draw threats, the Delaunay mesh, the incentre network and both paths for RViz.

    The array starts with a DELETEALL marker so that markers of an earlier plan
    vanish, then holds, by namespace:

    * ``threats``: with at most :data:`SPHERES_PER_THREAT_MAX` threats, one SPHERE per
      threat (ids 0..N-1) whose diameter is ``threat_diameter * F / max(F)``, floored
      at a fifth of `threat_diameter` so weak threats stay visible; above that, a
      single SPHERE_LIST of fixed diameter `threat_diameter` (a SPHERE_LIST has one
      scale).  Colour runs from yellow (weakest) to red (strongest) in both cases.
    * ``delaunay``: LINE_LIST of the Delaunay edges over `vertices`.
    * ``nodes``: SPHERE_LIST of the incentre nodes.
    * ``network``: LINE_LIST of the network edges over `nodes`.
    * ``initial_path`` and ``path``: LINE_STRIPs.

    A part that is None or empty (or a path of fewer than two points) is left out.

    Parameters
    ----------
    threat_positions : array_like
        Threat positions, shape (N, 3) [m].
    intensities : array_like
        Threat intensities, shape (N,), > 0.
    vertices : array_like
        Vertices of the Delaunay tetrahedralisation, shape (V, 3) [m].
    delaunay_edges : array_like
        Integer indices into `vertices`, shape (E, 2).
    nodes : array_like
        Incentre network nodes, shape (M, 3) [m].
    network_edges : array_like
        Integer indices into `nodes`, shape (K, 2).
    initial_path : array_like or None
        Network (Dijkstra) path, shape (n, 3) [m].
    path : array_like or None
        Final path, shape (m, 3) [m].
    frame_id : str
        Frame of all coordinates.
    stamp : builtin_interfaces.msg.Time
        Stamp for all markers.
    threat_diameter : float, optional
        Diameter of the strongest threat's sphere [m].
    node_diameter : float, optional
        Diameter of the network node spheres [m].
    line_width : float, optional
        Width of mesh, network and path lines [m]; paths are drawn twice as wide.

    Returns
    -------
    visualization_msgs.msg.MarkerArray
        DELETEALL followed by the markers above.

    Raises
    ------
    InputError
        On a wrong shape, NaN/inf, intensities that do not match the threats, or an
        edge index outside its vertex array.

    """
    header = make_header(frame_id, stamp)
    markers = [Marker(header=header, action=Marker.DELETEALL)]

    threats = as_points('threat_positions', threat_positions)
    strengths = np.asarray(intensities, dtype=np.float64).reshape(-1)
    if strengths.shape != (threats.shape[0],):
        raise InputError(
            f'intensities must have shape ({threats.shape[0]},), got {strengths.shape}')
    check_finite_rows('intensities', 'values', strengths)
    if threats.shape[0] > 0:
        peak = float(strengths.max())
        weights = strengths / peak if peak > 0.0 else np.ones_like(strengths)
        weights = np.clip(weights, 0.0, 1.0)
        colors = _threat_colors(weights)
        if threats.shape[0] <= SPHERES_PER_THREAT_MAX:
            diameters = threat_diameter * np.maximum(weights, 0.2)
            for i, ((x, y, z), d) in enumerate(zip(threats.tolist(), diameters.tolist())):
                sphere = _marker('threats', i, Marker.SPHERE, header, d, colors[i])
                sphere.pose.position = Point(x=x, y=y, z=z)
                markers.append(sphere)
        else:
            cloud = _marker('threats', 0, Marker.SPHERE_LIST, header, threat_diameter,
                            _rgba(1.0, 0.0, 0.0, 0.8))
            cloud.points = _to_point_msgs(threats)
            cloud.colors = colors
            markers.append(cloud)

    verts = as_points('vertices', vertices)
    mesh_edges = as_edges('delaunay_edges', delaunay_edges, verts.shape[0])
    if mesh_edges.shape[0] > 0:
        mesh = _marker('delaunay', 0, Marker.LINE_LIST, header, line_width,
                       _rgba(0.6, 0.6, 0.6, 0.4))
        mesh.points = _to_point_msgs(verts[mesh_edges].reshape(-1, 3))
        markers.append(mesh)

    node_pts = as_points('nodes', nodes)
    if node_pts.shape[0] > 0:
        node_marker = _marker('nodes', 0, Marker.SPHERE_LIST, header, node_diameter,
                              _rgba(0.1, 0.4, 1.0, 0.9))
        node_marker.points = _to_point_msgs(node_pts)
        markers.append(node_marker)

    net_edges = as_edges('network_edges', network_edges, node_pts.shape[0])
    if net_edges.shape[0] > 0:
        net = _marker('network', 0, Marker.LINE_LIST, header, line_width,
                      _rgba(0.1, 0.8, 0.3, 0.6))
        net.points = _to_point_msgs(node_pts[net_edges].reshape(-1, 3))
        markers.append(net)

    for ns, pts, color in (('initial_path', initial_path, _rgba(1.0, 0.6, 0.0, 1.0)),
                           ('path', path, _rgba(1.0, 0.0, 1.0, 1.0))):
        if pts is None:
            continue
        arr = as_points(ns, pts)
        if arr.shape[0] < 2:
            continue
        strip = _marker(ns, 0, Marker.LINE_STRIP, header, 2.0 * line_width, color)
        strip.points = _to_point_msgs(arr)
        markers.append(strip)

    return MarkerArray(markers=markers)


#: The terrain is drawn on at most this many grid cells per side (subsampled beyond).
TERRAIN_CELLS_MAX = 48


def airspace_markers(airspace, frame_id: str, stamp: Time,
                     line_width: float = 0.2) -> list[Marker]:
    """Draw no-fly zones (namespace ``zones``) and terrain (``terrain``) for RViz.

    Spheres, cylinders and boxes are SPHERE, CYLINDER and CUBE markers; a prism is a
    LINE_LIST of its floor, ceiling and vertical edges; the terrain is a TRIANGLE_LIST
    over at most :data:`TERRAIN_CELLS_MAX` cells per side (every k-th grid point).

    Parameters
    ----------
    airspace : threat_planner.core.world.airspace.Airspace
        Zones and terrain.
    frame_id : str
        Frame of the markers.
    stamp : builtin_interfaces.msg.Time
        Their stamp.
    line_width : float, optional
        Width of prism edges [m].

    Returns
    -------
    list of Marker
        The markers, to append to a MarkerArray after its DELETEALL.

    """
    header = make_header(frame_id, stamp)
    out = []
    solid = zones_to_markers(airspace.zones, frame_id, stamp, line_width).markers[1:]
    for i, (zone, m) in enumerate(zip(airspace.zones, solid)):
        m.ns, m.id = 'zones', i
        m.text = zone.label
        if zone.kind == 'prism':
            ring = np.vstack([zone.polygon, zone.polygon[:1]])
            lo = np.column_stack([ring, np.full(len(ring), zone.z_min)])
            hi = np.column_stack([ring, np.full(len(ring), zone.z_max)])
            segs = [np.stack([lo[:-1], lo[1:]], 1), np.stack([hi[:-1], hi[1:]], 1),
                    np.stack([lo[:-1], hi[:-1]], 1)]
            m.type = Marker.LINE_LIST
            m.points = _to_point_msgs(np.concatenate(segs).reshape(-1, 3))
            m.scale.y = m.scale.z = m.scale.x
            m.color = _rgba(0.9, 0.1, 0.1, 0.9)
        out.append(m)
    t = airspace.terrain
    if t is not None:
        rows, cols = t.heights.shape
        step = max(1, -(-max(rows, cols) // TERRAIN_CELLS_MAX))
        r = np.unique(np.r_[np.arange(0, rows, step), rows - 1])
        c = np.unique(np.r_[np.arange(0, cols, step), cols - 1])
        xx, yy = np.meshgrid(t.origin[0] + c * t.resolution, t.origin[1] + r * t.resolution)
        grid = np.dstack([xx, yy, t.heights[np.ix_(r, c)]])
        a, b = grid[:-1, :-1], grid[:-1, 1:]
        d, e = grid[1:, :-1], grid[1:, 1:]
        tris = np.stack([a, b, e, a, e, d], axis=2).reshape(-1, 3)
        surface = _marker('terrain', 0, Marker.TRIANGLE_LIST, header, 1.0,
                          _rgba(0.55, 0.45, 0.3, 0.7))
        surface.pose.orientation.w = 1.0
        surface.points = _to_point_msgs(tris)
        out.append(surface)
    return out
