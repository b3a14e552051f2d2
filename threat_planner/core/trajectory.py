"""A path in time: when the UAV passes each point at cruise speed, and where it points.

The planner makes a path (a polyline of points [m]); flown at a constant cruise speed it
becomes a trajectory. :func:`point_times` gives the time over each point, :func:`headings`
the direction of flight there, :func:`yaw_pitch` and :func:`quaternions` the attitude that
points the body x axis (the nose) along it with zero roll, as ROS poses carry it (REP-103:
x forward, y left, z up). Numpy in, numpy out; nothing here changes the path.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.errors import InputError

__all__ = ['MIN_SEGMENT_M', 'eta', 'heading_quaternions', 'headings', 'point_times',
           'quaternion_yaw_pitch', 'quaternions', 'segment_lengths', 'yaw_pitch']

#: Segments shorter than this [m] carry no usable direction (rounding noise would give an
#: arbitrary one): their points take a neighbour's heading.
MIN_SEGMENT_M = 1e-9


def _points(points: ArrayLike) -> NDArray[np.float64]:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f'points: expected shape (M, 3), got {list(pts.shape)}')
    if not np.all(np.isfinite(pts)):
        raise InputError('points: must be finite (no NaN or inf)')
    return pts


def _speed(speed_mps: object) -> float:
    if isinstance(speed_mps, (bool, str, bytes)) or not isinstance(speed_mps, numbers.Real):
        raise InputError(f'speed_mps: must be a number > 0, got {speed_mps!r}')
    v = float(speed_mps)
    if not (math.isfinite(v) and v > 0.0):
        raise InputError(f'speed_mps: must be finite and > 0, got {v!r}')
    return v


def segment_lengths(points: ArrayLike) -> NDArray[np.float64]:
    """Return the length of each segment of a polyline.

    Parameters
    ----------
    points : array_like
        Points, shape (M, 3) [m].

    Returns
    -------
    ndarray
        Lengths, shape (max(M - 1, 0),) [m].

    Raises
    ------
    InputError
        If `points` is not (M, 3) or holds NaN or inf.

    """
    d = np.diff(_points(points), axis=0)
    # einsum, not linalg.norm of a whole vector: one summation order on every CPU.
    return np.sqrt(np.einsum('ij,ij->i', d, d))


def point_times(points: ArrayLike, speed_mps: float, t0: float = 0.0) -> NDArray[np.float64]:
    """Return the time over each point of a path flown at a constant speed.

    Parameters
    ----------
    points : array_like
        Points, shape (M, 3) [m].
    speed_mps : float
        Cruise speed, finite and > 0 [m/s].
    t0 : float
        Time over the first point [s].

    Returns
    -------
    ndarray
        ``t0`` plus the polyline length up to each point over the speed, shape (M,) [s];
        non-decreasing (equal across a zero-length segment).

    Raises
    ------
    InputError
        For bad points, a speed that is not finite and > 0, or a t0 that is not finite.

    """
    lengths = segment_lengths(points)
    v = _speed(speed_mps)
    if not math.isfinite(float(t0)):
        raise InputError(f't0: must be finite, got {float(t0)!r}')
    n = len(lengths) + 1 if len(np.asarray(points)) else 0
    out = np.empty(n, dtype=np.float64)
    if n:
        out[0] = 0.0
        np.cumsum(lengths, out=out[1:])
    return float(t0) + out / v


def eta(points: ArrayLike, speed_mps: float) -> float:
    """Return the flight time from the first point to the last [s] (0 for under 2 points)."""
    times = point_times(points, speed_mps)
    return float(times[-1]) if len(times) else 0.0


def headings(points: ArrayLike) -> NDArray[np.float64]:
    """Return the unit direction of flight at each point of a path.

    Point k looks along segment k -> k + 1 and the last point along the last segment.
    A point whose segment is shorter than :data:`MIN_SEGMENT_M` takes the heading of the
    nearest usable segment before it (leading ones the first usable one after them). A
    path with no usable segment (one point, or all points equal) heads along +x, the
    identity attitude.

    Parameters
    ----------
    points : array_like
        Points, shape (M, 3) [m].

    Returns
    -------
    ndarray
        Unit vectors, shape (M, 3) [1].

    Raises
    ------
    InputError
        If `points` is not (M, 3) or holds NaN or inf.

    """
    pts = _points(points)
    out = np.zeros((len(pts), 3), dtype=np.float64)
    out[:, 0] = 1.0
    if len(pts) < 2:
        return out
    seg = np.diff(pts, axis=0)
    length = np.sqrt(np.einsum('ij,ij->i', seg, seg))
    valid = length > MIN_SEGMENT_M
    if not valid.any():
        return out
    # Index of the latest usable segment at or before each one (the first usable before it).
    idx = np.maximum.accumulate(np.where(valid, np.arange(valid.size), -1))
    idx[idx < 0] = int(np.argmax(valid))
    unit = seg[idx] / length[idx, None]
    out[:-1] = unit
    out[-1] = unit[-1]
    return out


def yaw_pitch(headings: ArrayLike) -> NDArray[np.float64]:
    """Return the yaw and pitch of direction vectors.

    Parameters
    ----------
    headings : array_like
        Directions, shape (M, 3) (any non-zero length).

    Returns
    -------
    ndarray
        Shape (M, 2): yaw about +z from +x towards +y, in (-pi, pi], and pitch above the
        horizontal, positive nose-up, in [-pi/2, pi/2] [rad].

    """
    h = np.asarray(headings, dtype=np.float64).reshape(-1, 3)
    return np.column_stack([np.arctan2(h[:, 1], h[:, 0]),
                            np.arctan2(h[:, 2], np.hypot(h[:, 0], h[:, 1]))])


def quaternions(yaw_pitch: ArrayLike) -> NDArray[np.float64]:
    """Return the attitude quaternions of yaw and pitch with zero roll.

    Parameters
    ----------
    yaw_pitch : array_like
        Shape (M, 2): yaw about +z and pitch positive nose-up [rad], as :func:`yaw_pitch`.

    Returns
    -------
    ndarray
        Unit quaternions (x, y, z, w), shape (M, 4), turning the body x axis to the
        heading: q = q_z(yaw) q_y(-pitch), since under REP-103 a positive rotation about
        +y points the nose down.

    """
    yp = np.asarray(yaw_pitch, dtype=np.float64).reshape(-1, 2)
    cy, sy = np.cos(yp[:, 0] / 2.0), np.sin(yp[:, 0] / 2.0)
    # The half angle of the rotation about +y, -pitch.
    cp, sp = np.cos(-yp[:, 1] / 2.0), np.sin(-yp[:, 1] / 2.0)
    return np.column_stack([-sy * sp, cy * sp, sy * cp, cy * cp])


def quaternion_yaw_pitch(quats: ArrayLike) -> NDArray[np.float64]:
    """Return the yaw and pitch [rad] of zero-roll quaternions (x, y, z, w), shape (M, 2).

    The inverse of :func:`quaternions`: the body x axis turned by each quaternion, read
    back as :func:`yaw_pitch` reads a heading.
    """
    q = np.asarray(quats, dtype=np.float64).reshape(-1, 4)
    x, y, z, w = q.T
    nose = np.column_stack([1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z),
                            2.0 * (x * z - w * y)])
    return yaw_pitch(nose)


def heading_quaternions(points: ArrayLike) -> NDArray[np.float64]:
    """Return the attitude (x, y, z, w) along a path at each point, shape (M, 4).

    ``quaternions(yaw_pitch(headings(points)))``: the nose along :func:`headings`, zero
    roll; identity where the path has no direction.
    """
    return quaternions(yaw_pitch(headings(points)))
