"""
Conversions between ROS 2 messages and the numpy arrays of the planning core.

The planning core never imports rclpy or message packages; the node calls these
functions at its edge.  Every reader validates what it decodes and raises
:class:`threat_planner.errors.InputError` with a one-line message naming the bad
field and value, so that a bad message is refused before it reaches the planner.

Conventions: positions are in metres [m] in the message's frame, angles follow
REP-103 (x forward, y left, z up; a positive pitch about y points the nose down).
"""

from typing import Mapping, Optional, Sequence, Tuple

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped, Quaternion
from nav_msgs.msg import Path
import numpy as np
from numpy.typing import ArrayLike, NDArray
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from threat_planner.errors import InputError

__all__ = [
    'PLAN_STATUS_NAME',
    'SPHERES_PER_THREAT_MAX',
    'network_markers',
    'ns_to_stamp',
    'path_from_msg',
    'path_to_msg',
    'plan_info_msg',
    'plan_info_values',
    'point_from_pose_stamped',
    'pointcloud2_from_threats',
    'stamp_to_ns',
    'threats_from_pointcloud2',
    'threats_from_pose_array',
]

#: Name of the DiagnosticStatus written by :func:`plan_info_msg`.
PLAN_STATUS_NAME = 'threat_planner: plan'

#: Above this many threats, :func:`network_markers` draws one fixed-size SPHERE_LIST
#: instead of one intensity-scaled SPHERE per threat (RViz cost grows per marker).
SPHERES_PER_THREAT_MAX = 500

_NS_PER_S = 1_000_000_000
_INT32_MAX = 2**31 - 1

# Segments shorter than this carry no usable direction (rounding noise would give
# an arbitrary heading), so path_to_msg reuses the previous direction instead.
_MIN_SEGMENT_M = 1e-9

_CLOUD_FIELDS = ('x', 'y', 'z', 'intensity')
# numpy's largest itemsize (a C int): a longer point or row cannot be decoded (nor sent).
_MAX_STEP = 2**31 - 1
_FLOAT_SIZES = {PointField.FLOAT32: 4, PointField.FLOAT64: 8}
_DATATYPE_NAMES = {
    PointField.INT8: 'INT8',
    PointField.UINT8: 'UINT8',
    PointField.INT16: 'INT16',
    PointField.UINT16: 'UINT16',
    PointField.INT32: 'INT32',
    PointField.UINT32: 'UINT32',
    PointField.FLOAT32: 'FLOAT32',
    PointField.FLOAT64: 'FLOAT64',
}

_LEVELS = {
    'OK': DiagnosticStatus.OK,
    'WARN': DiagnosticStatus.WARN,
    'ERROR': DiagnosticStatus.ERROR,
}


# --------------------------------------------------------------------------- time


def stamp_to_ns(stamp: Time) -> int:
    """
    Convert a ROS time stamp to integer nanoseconds.

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time
        Stamp with ``sec`` [s] and ``nanosec`` [ns].

    Returns
    -------
    int
        ``sec * 10**9 + nanosec`` [ns].

    """
    return int(stamp.sec) * _NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """
    Convert integer nanoseconds to a ROS time stamp.

    Parameters
    ----------
    ns : int
        Time since the epoch [ns]; must be non-negative and fit the int32 seconds field.

    Returns
    -------
    builtin_interfaces.msg.Time
        Stamp whose ``nanosec`` is in [0, 10**9).

    Raises
    ------
    InputError
        If `ns` is negative or too large for ``Time.sec``.

    """
    ns = int(ns)
    if ns < 0:
        raise InputError(f'time stamp must be non-negative, got {ns} ns')
    sec, nanosec = divmod(ns, _NS_PER_S)
    if sec > _INT32_MAX:
        raise InputError(f'time stamp {ns} ns overflows the int32 seconds field')
    return Time(sec=sec, nanosec=nanosec)


def _header(frame_id: str, stamp: Time) -> Header:
    return Header(frame_id=frame_id, stamp=stamp)


# ----------------------------------------------------------------- validation helpers


def _check_frame(kind: str, frame_id: str, expected_frame: str) -> None:
    if frame_id != expected_frame:
        raise InputError(
            f'{kind} frame_id {frame_id!r} does not match expected frame {expected_frame!r}')


def _check_count(kind: str, count: int, max_points: Optional[int]) -> None:
    if max_points is not None and count > max_points:
        raise InputError(f'{kind} has {count} points, more than max_points={max_points}')


def _check_finite_rows(kind: str, what: str, values: NDArray[np.float64]) -> None:
    bad = ~np.isfinite(values)
    if bad.ndim > 1:
        bad = bad.any(axis=1)
    if bad.any():
        first = int(np.argmax(bad))
        raise InputError(
            f'{kind} has {int(bad.sum())} non-finite {what} (first at index {first}: '
            f'{values[first].tolist()})')


def _check_positive(kind: str, intensities: NDArray[np.float64]) -> None:
    bad = intensities <= 0.0
    if bad.any():
        first = int(np.argmax(bad))
        raise InputError(
            f'{kind} has {int(bad.sum())} non-positive intensities (first at index {first}: '
            f'{float(intensities[first])!r})')


def _as_points(name: str, points: ArrayLike) -> NDArray[np.float64]:
    """Return `points` as an (n, 3) float64 array, refusing other shapes and NaN/inf."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f'{name} must have shape (n, 3), got {arr.shape}')
    _check_finite_rows(name, 'points', arr)
    return arr


def _as_edges(name: str, edges: ArrayLike, n_vertices: int) -> NDArray[np.intp]:
    arr = np.asarray(edges)
    if arr.size == 0:
        return np.empty((0, 2), dtype=np.intp)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise InputError(f'{name} must have shape (k, 2), got {arr.shape}')
    if not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f'{name} must hold integer indices, got dtype {arr.dtype}')
    bad = (arr < 0) | (arr >= n_vertices)
    if bad.any():
        row = int(np.argmax(bad.any(axis=1)))
        raise InputError(
            f'{name} row {row} {arr[row].tolist()} indexes outside 0..{n_vertices - 1}')
    return arr.astype(np.intp, copy=False)


# -------------------------------------------------------------------- PointCloud2


def _cloud_point_dtype(msg: PointCloud2) -> np.dtype:
    """Build the structured dtype of one point from the x, y, z, intensity fields."""
    by_name = {}
    for field in msg.fields:
        if field.name in _CLOUD_FIELDS:
            if field.name in by_name:
                raise InputError(f'PointCloud2 has duplicate field {field.name!r}')
            by_name[field.name] = field
    missing = [name for name in _CLOUD_FIELDS if name not in by_name]
    if missing:
        present = [f.name for f in msg.fields]
        raise InputError(f'PointCloud2 is missing field(s) {missing}; fields are {present}')

    byte_order = '>' if msg.is_bigendian else '<'
    formats, offsets, spans = [], [], []
    for name in _CLOUD_FIELDS:
        field = by_name[name]
        if field.datatype not in _FLOAT_SIZES:
            type_name = _DATATYPE_NAMES.get(field.datatype, 'unknown')
            raise InputError(
                f'PointCloud2 field {name!r} has datatype {type_name} ({field.datatype}); '
                'expected FLOAT32 (7) or FLOAT64 (8)')
        if field.count != 1:
            raise InputError(
                f'PointCloud2 field {name!r} has count {field.count}; expected 1')
        size = _FLOAT_SIZES[field.datatype]
        formats.append(f'{byte_order}f{size}')
        offsets.append(int(field.offset))
        spans.append((int(field.offset), int(field.offset) + size, name))

    # Overlapping coordinates would decode silently as garbage, so refuse them.
    spans.sort()
    for (_, end, name), (start, _, next_name) in zip(spans, spans[1:]):
        if start < end:
            raise InputError(
                f'PointCloud2 fields {name!r} and {next_name!r} overlap '
                f'(offset {start} < end {end})')
    needed = max(end for _, end, _ in spans)
    if msg.point_step < needed:
        raise InputError(
            f'PointCloud2 point_step {msg.point_step} is smaller than the {needed} bytes '
            'its fields need')
    if msg.point_step > _MAX_STEP:
        raise InputError(
            f'PointCloud2 point_step {msg.point_step} is larger than {_MAX_STEP} bytes')
    return np.dtype({'names': list(_CLOUD_FIELDS), 'formats': formats,
                     'offsets': offsets, 'itemsize': int(msg.point_step)})


def threats_from_pointcloud2(
    msg: PointCloud2,
    expected_frame: str,
    max_points: Optional[int] = None,
) -> Tuple[NDArray[np.float64], NDArray[np.float64]]:
    """
    Decode threat positions and intensities from a PointCloud2.

    The cloud must carry float fields ``x``, ``y``, ``z`` [m] and ``intensity``
    (FLOAT32 or FLOAT64, ``count`` 1) at any offsets and in any order; other fields
    are ignored.  ``is_bigendian``, ``point_step`` and ``row_step`` (row padding) are
    honoured, and all ``height * width`` points are decoded without a Python loop.

    Parameters
    ----------
    msg : sensor_msgs.msg.PointCloud2
        Threat cloud.
    expected_frame : str
        Frame the positions must be expressed in; compared with ``header.frame_id``.
    max_points : int, optional
        Largest accepted ``height * width``; checked before any decoding so that an
        oversized cloud is refused cheaply.  None (default) means no limit.

    Returns
    -------
    positions : NDArray[np.float64]
        Threat positions, shape (N, 3) [m].
    intensities : NDArray[np.float64]
        Threat intensities, shape (N,), all finite and > 0.

    Raises
    ------
    InputError
        On a frame mismatch, too many points, a missing, non-float, multi-count or
        overlapping field, a ``point_step`` or ``row_step`` too small for the layout
        (or over 2**31 - 1 bytes),
        a data length other than ``row_step * height``, non-finite values or a
        non-positive intensity.

    """
    _check_frame('PointCloud2', msg.header.frame_id, expected_frame)
    height, width = int(msg.height), int(msg.width)
    _check_count('PointCloud2', height * width, max_points)
    point_dtype = _cloud_point_dtype(msg)

    row_step = int(msg.row_step)
    if row_step < width * msg.point_step:
        raise InputError(
            f'PointCloud2 row_step {row_step} is smaller than width*point_step = '
            f'{width}*{msg.point_step} = {width * msg.point_step}')
    if len(msg.data) != row_step * height:
        raise InputError(
            f'PointCloud2 data has {len(msg.data)} bytes; row_step*height = '
            f'{row_step}*{height} = {row_step * height}')
    if height * width == 0:
        return np.empty((0, 3), dtype=np.float64), np.empty(0, dtype=np.float64)

    if row_step > _MAX_STEP:
        raise InputError(f'PointCloud2 row_step {row_step} is larger than {_MAX_STEP} bytes')
    # A row dtype with itemsize row_step skips row padding without copying the buffer.
    row_dtype = np.dtype({'names': ['points'], 'formats': [(point_dtype, (width,))],
                          'offsets': [0], 'itemsize': row_step})
    points = np.frombuffer(msg.data, dtype=row_dtype, count=height)['points'].reshape(-1)
    positions = np.empty((points.shape[0], 3), dtype=np.float64)
    positions[:, 0] = points['x']
    positions[:, 1] = points['y']
    positions[:, 2] = points['z']
    intensities = points['intensity'].astype(np.float64)

    _check_finite_rows('PointCloud2', 'positions', positions)
    _check_finite_rows('PointCloud2', 'intensities', intensities)
    _check_positive('PointCloud2', intensities)
    return positions, intensities


def pointcloud2_from_threats(
    positions: ArrayLike,
    intensities: ArrayLike,
    frame_id: str,
    stamp: Time,
) -> PointCloud2:
    """
    Encode threats as a dense, little-endian PointCloud2.

    Built by hand because sensor_msgs_py is not among the installed wheels.

    Parameters
    ----------
    positions : array_like
        Threat positions, shape (N, 3) [m].
    intensities : array_like
        Threat intensities, shape (N,).
    frame_id : str
        Frame of `positions`.
    stamp : builtin_interfaces.msg.Time
        Header stamp.

    Returns
    -------
    sensor_msgs.msg.PointCloud2
        Cloud of height 1 and width N with FLOAT32 fields x, y, z, intensity at
        offsets 0, 4, 8, 12 (``point_step`` 16); values are rounded to float32.

    Raises
    ------
    InputError
        If the shapes are wrong or disagree.

    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim == 1 and pos.size == 0:
        pos = pos.reshape(0, 3)
    inten = np.asarray(intensities, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise InputError(f'positions must have shape (N, 3), got {pos.shape}')
    if inten.shape != (pos.shape[0],):
        raise InputError(
            f'intensities must have shape ({pos.shape[0]},) to match positions, '
            f'got {inten.shape}')

    point_dtype = np.dtype([(name, '<f4') for name in _CLOUD_FIELDS])
    packed = np.empty(pos.shape[0], dtype=point_dtype)
    packed['x'], packed['y'], packed['z'] = pos[:, 0], pos[:, 1], pos[:, 2]
    packed['intensity'] = inten

    msg = PointCloud2()
    msg.header = _header(frame_id, stamp)
    msg.height = 1
    msg.width = pos.shape[0]
    msg.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, name in enumerate(_CLOUD_FIELDS)]
    msg.is_bigendian = False
    msg.point_step = point_dtype.itemsize
    msg.row_step = point_dtype.itemsize * pos.shape[0]
    msg.data = packed.tobytes()
    msg.is_dense = bool(np.isfinite(pos).all() and np.isfinite(inten).all())
    return msg


# ---------------------------------------------------------------------- poses


def threats_from_pose_array(
    msg: PoseArray,
    expected_frame: str,
    default_intensity: float,
    max_points: Optional[int] = None,
) -> Tuple[NDArray[np.float64], NDArray[np.float64]]:
    """
    Read threat positions from a PoseArray; every threat gets `default_intensity`.

    Orientations are ignored: a threat is a point source.

    Parameters
    ----------
    msg : geometry_msgs.msg.PoseArray
        Threat poses.
    expected_frame : str
        Frame the positions must be expressed in; compared with ``header.frame_id``.
    default_intensity : float
        Intensity given to every threat; must be finite and > 0.
    max_points : int, optional
        Largest accepted number of poses; None (default) means no limit.

    Returns
    -------
    positions : NDArray[np.float64]
        Threat positions, shape (N, 3) [m].
    intensities : NDArray[np.float64]
        Shape (N,), all equal to `default_intensity`.

    Raises
    ------
    InputError
        On a frame mismatch, too many poses, a non-finite position or a non-finite or
        non-positive `default_intensity`.

    """
    _check_frame('PoseArray', msg.header.frame_id, expected_frame)
    intensity = float(default_intensity)
    if not np.isfinite(intensity) or intensity <= 0.0:
        raise InputError(f'default_intensity must be finite and > 0, got {intensity!r}')
    _check_count('PoseArray', len(msg.poses), max_points)
    positions = np.array([(p.position.x, p.position.y, p.position.z) for p in msg.poses],
                         dtype=np.float64).reshape(-1, 3)
    _check_finite_rows('PoseArray', 'positions', positions)
    return positions, np.full(positions.shape[0], intensity)


def point_from_pose_stamped(
    msg: PoseStamped,
    expected_frame: str,
    name: str = 'PoseStamped',
) -> NDArray[np.float64]:
    """
    Read the position of a PoseStamped (a start or goal).

    Parameters
    ----------
    msg : geometry_msgs.msg.PoseStamped
        Pose; its orientation is ignored.
    expected_frame : str
        Frame the position must be expressed in; compared with ``header.frame_id``.
    name : str, optional
        What the pose is (for example ``'start'`` or ``'goal_pose'``), used in errors.

    Returns
    -------
    NDArray[np.float64]
        Position, shape (3,) [m].

    Raises
    ------
    InputError
        On a frame mismatch or a non-finite coordinate.

    """
    _check_frame(name, msg.header.frame_id, expected_frame)
    p = msg.pose.position
    point = np.array([p.x, p.y, p.z], dtype=np.float64)
    if not np.isfinite(point).all():
        raise InputError(f'{name} position must be finite, got {point.tolist()}')
    return point


# ----------------------------------------------------------------------- paths


def _forward_fill(valid: NDArray[np.bool_]) -> NDArray[np.intp]:
    """Index of the latest valid entry at or before each position (first valid before it)."""
    idx = np.where(valid, np.arange(valid.size), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = int(np.argmax(valid))
    return idx


def _heading_quaternions(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """
    Quaternions (x, y, z, w) turning the body x axis along the path at each point.

    Pose i looks along segment i -> i + 1 and the last pose along the last segment.
    Zero-length segments reuse the previous direction (leading ones the first usable
    one); a path with no usable segment gets identity orientations.
    """
    n = points.shape[0]
    quats = np.zeros((n, 4), dtype=np.float64)
    quats[:, 3] = 1.0
    if n < 2:
        return quats
    seg = np.diff(points, axis=0)
    valid = np.linalg.norm(seg, axis=1) > _MIN_SEGMENT_M
    if not valid.any():
        return quats
    seg = seg[_forward_fill(valid)]
    seg = np.vstack([seg, seg[-1:]])

    yaw = np.arctan2(seg[:, 1], seg[:, 0])
    # REP-103: rotating +x about +y by a positive angle points it down, so a climb
    # is a negative pitch.
    pitch = -np.arctan2(seg[:, 2], np.hypot(seg[:, 0], seg[:, 1]))
    cy, sy = np.cos(yaw / 2.0), np.sin(yaw / 2.0)
    cp, sp = np.cos(pitch / 2.0), np.sin(pitch / 2.0)
    # q = q_z(yaw) * q_y(pitch): intrinsic Z-Y-X with zero roll.
    quats[:, 0] = -sy * sp
    quats[:, 1] = cy * sp
    quats[:, 2] = sy * cp
    quats[:, 3] = cy * cp
    return quats


def path_to_msg(points: ArrayLike, frame_id: str, stamp: Time) -> Path:
    """
    Build a nav_msgs/Path whose poses point along the flight direction.

    Each pose's orientation turns the body x axis (the nose) along the segment to
    the next waypoint with zero roll; the last pose keeps the last segment's
    direction.  Zero-length segments reuse the previous direction.

    Parameters
    ----------
    points : array_like
        Waypoints, shape (n, 3) [m]; n may be 0.
    frame_id : str
        Frame of the waypoints, used for the path and every pose header.
    stamp : builtin_interfaces.msg.Time
        Stamp for the path and every pose header.

    Returns
    -------
    nav_msgs.msg.Path
        Path with n poses.

    Raises
    ------
    InputError
        If `points` is not (n, 3) or holds NaN/inf.

    """
    pts = _as_points('path points', points)
    quats = _heading_quaternions(pts)
    header = _header(frame_id, stamp)
    msg = Path(header=header)
    msg.poses = [
        PoseStamped(
            header=_header(frame_id, stamp),
            pose=Pose(position=Point(x=px, y=py, z=pz),
                      orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
        for (px, py, pz), (qx, qy, qz, qw) in zip(pts.tolist(), quats.tolist())
    ]
    return msg


def path_from_msg(msg: Path) -> NDArray[np.float64]:
    """
    Read the waypoints of a nav_msgs/Path.

    Parameters
    ----------
    msg : nav_msgs.msg.Path
        Path; orientations and per-pose headers are ignored.

    Returns
    -------
    NDArray[np.float64]
        Waypoints, shape (n, 3) [m].

    """
    return np.array([(p.pose.position.x, p.pose.position.y, p.pose.position.z)
                     for p in msg.poses], dtype=np.float64).reshape(-1, 3)


# --------------------------------------------------------------------- markers


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
    header = _header(frame_id, stamp)
    markers = [Marker(header=header, action=Marker.DELETEALL)]

    threats = _as_points('threat_positions', threat_positions)
    strengths = np.asarray(intensities, dtype=np.float64).reshape(-1)
    if strengths.shape != (threats.shape[0],):
        raise InputError(
            f'intensities must have shape ({threats.shape[0]},), got {strengths.shape}')
    _check_finite_rows('intensities', 'values', strengths)
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

    verts = _as_points('vertices', vertices)
    mesh_edges = _as_edges('delaunay_edges', delaunay_edges, verts.shape[0])
    if mesh_edges.shape[0] > 0:
        mesh = _marker('delaunay', 0, Marker.LINE_LIST, header, line_width,
                       _rgba(0.6, 0.6, 0.6, 0.4))
        mesh.points = _to_point_msgs(verts[mesh_edges].reshape(-1, 3))
        markers.append(mesh)

    node_pts = _as_points('nodes', nodes)
    if node_pts.shape[0] > 0:
        node_marker = _marker('nodes', 0, Marker.SPHERE_LIST, header, node_diameter,
                              _rgba(0.1, 0.4, 1.0, 0.9))
        node_marker.points = _to_point_msgs(node_pts)
        markers.append(node_marker)

    net_edges = _as_edges('network_edges', network_edges, node_pts.shape[0])
    if net_edges.shape[0] > 0:
        net = _marker('network', 0, Marker.LINE_LIST, header, line_width,
                      _rgba(0.1, 0.8, 0.3, 0.6))
        net.points = _to_point_msgs(node_pts[net_edges].reshape(-1, 3))
        markers.append(net)

    for ns, pts, color in (('initial_path', initial_path, _rgba(1.0, 0.6, 0.0, 1.0)),
                           ('path', path, _rgba(1.0, 0.0, 1.0, 1.0))):
        if pts is None:
            continue
        arr = _as_points(ns, pts)
        if arr.shape[0] < 2:
            continue
        strip = _marker(ns, 0, Marker.LINE_STRIP, header, 2.0 * line_width, color)
        strip.points = _to_point_msgs(arr)
        markers.append(strip)

    return MarkerArray(markers=markers)


# ----------------------------------------------------------------- diagnostics


def _format_value(value: object) -> str:
    # bool before int (bool is an int); numpy scalars via Python types because
    # numpy 2 reprs them as 'np.float64(...)'.
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        # repr is the shortest string that float() maps back to the same double.
        return repr(float(value))
    return str(value)


def plan_info_msg(
    status: str,
    message: str,
    values: Mapping[str, object],
    stamp: Time,
    hardware_id: str = 'threat_planner',
) -> DiagnosticArray:
    """
    Report a planning result as a DiagnosticArray with one status.

    Parameters
    ----------
    status : {'OK', 'WARN', 'ERROR'}
        Outcome, mapped to the DiagnosticStatus level.
    message : str
        One-line summary.
    values : Mapping[str, object]
        Key/value details in order; floats are written with ``repr`` so that
        ``float(text)`` gives back the same value, ints as integers, others with ``str``.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    hardware_id : str, optional
        DiagnosticStatus hardware id.

    Returns
    -------
    diagnostic_msgs.msg.DiagnosticArray
        Array with one status named :data:`PLAN_STATUS_NAME`.

    Raises
    ------
    InputError
        If `status` is not one of 'OK', 'WARN', 'ERROR'.

    """
    if status not in _LEVELS:
        raise InputError(f"status must be 'OK', 'WARN' or 'ERROR', got {status!r}")
    diag = DiagnosticStatus(
        level=_LEVELS[status], name=PLAN_STATUS_NAME, message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=_format_value(v)) for k, v in values.items()])
    return DiagnosticArray(header=Header(stamp=stamp), status=[diag])


def plan_info_values(msg: DiagnosticArray) -> dict[str, str]:
    """
    Read back the key/values written by :func:`plan_info_msg`.

    Parameters
    ----------
    msg : diagnostic_msgs.msg.DiagnosticArray
        Array holding a status named :data:`PLAN_STATUS_NAME`.

    Returns
    -------
    dict[str, str]
        Keys and their string values, in message order.

    Raises
    ------
    InputError
        If no status of that name is present.

    """
    for diag in msg.status:
        if diag.name == PLAN_STATUS_NAME:
            return {kv.key: kv.value for kv in diag.values}
    names: Sequence[str] = [d.name for d in msg.status]
    raise InputError(f'DiagnosticArray has no status {PLAN_STATUS_NAME!r}; statuses are {names}')
