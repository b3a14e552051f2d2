"""Paths as nav_msgs/Path, poses along the flight direction."""


from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from nav_msgs.msg import Path
import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.ros.conversions._common import as_points, make_header

# Segments shorter than this carry no usable direction (rounding noise would give
# an arbitrary heading), so path_to_msg reuses the previous direction instead.
_MIN_SEGMENT_M = 1e-9


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
    pts = as_points('path points', points)
    quats = _heading_quaternions(pts)
    header = make_header(frame_id, stamp)
    msg = Path(header=header)
    msg.poses = [
        PoseStamped(
            header=make_header(frame_id, stamp),
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
