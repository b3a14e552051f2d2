"""Paths as nav_msgs/Path: poses along the flight direction, stamped with their times."""

from typing import Optional

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from nav_msgs.msg import Path
import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.trajectory import heading_quaternions
from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import (as_points, make_header, ns_to_stamp,
                                                    stamp_to_ns)


def _pose_stamps(stamp: Time, times: Optional[ArrayLike], n: int) -> list[Time]:
    """Return the stamp of each pose: `stamp` plus its time [s], to the nanosecond."""
    if times is None:
        return [stamp] * n
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if t.shape != (n,):
        raise InputError(f'path times: expected {n} (one per point), got {t.size}')
    if not (np.all(np.isfinite(t)) and np.all(t >= 0.0)):
        raise InputError('path times: must be finite and >= 0 [s]')
    t0 = stamp_to_ns(stamp)
    return [ns_to_stamp(t0 + int(dt)) for dt in np.rint(t * 1e9)]


def path_to_msg(points: ArrayLike, frame_id: str, stamp: Time,
                times: Optional[ArrayLike] = None) -> Path:
    """
    Build a nav_msgs/Path whose poses point along the flight direction.

    Each pose's orientation turns the body x axis (the nose) along the segment to
    the next waypoint with zero roll (:func:`threat_planner.core.trajectory.headings`);
    the last pose keeps the last segment's direction, and zero-length segments reuse a
    neighbour's.

    Parameters
    ----------
    points : array_like
        Waypoints, shape (n, 3) [m]; n may be 0.
    frame_id : str
        Frame of the waypoints, used for the path and every pose header.
    stamp : builtin_interfaces.msg.Time
        Stamp of the path header: the trajectory's t0.
    times : array_like, optional
        Time over each waypoint after `stamp`, shape (n,) [s] (for example
        :func:`threat_planner.core.trajectory.point_times`); pose k is stamped
        ``stamp + times[k]``. None stamps every pose with `stamp`.

    Returns
    -------
    nav_msgs.msg.Path
        Path with n poses.

    Raises
    ------
    InputError
        If `points` is not (n, 3) or holds NaN/inf, or `times` is not n finite
        non-negative values.

    """
    pts = as_points('path points', points)
    quats = heading_quaternions(pts)
    stamps = _pose_stamps(stamp, times, len(pts))
    msg = Path(header=make_header(frame_id, stamp))
    msg.poses = [
        PoseStamped(
            header=make_header(frame_id, at),
            pose=Pose(position=Point(x=px, y=py, z=pz),
                      orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
        for (px, py, pz), (qx, qy, qz, qw), at in zip(pts.tolist(), quats.tolist(), stamps)
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
