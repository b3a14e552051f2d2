"""Stamps, headers and the checks every message reader shares."""

from typing import Optional

from builtin_interfaces.msg import Time
import numpy as np
from numpy.typing import ArrayLike, NDArray
from std_msgs.msg import Header

from threat_planner.errors import InputError

_NS_PER_S = 1_000_000_000
_INT32_MAX = 2**31 - 1


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


def make_header(frame_id: str, stamp: Time) -> Header:
    """Return a std_msgs/Header with this frame and stamp."""
    return Header(frame_id=frame_id, stamp=stamp)


def check_frame(kind: str, frame_id: str, expected_frame: str) -> None:
    """Refuse a message of another frame than the node's."""
    if frame_id != expected_frame:
        raise InputError(
            f'{kind} frame_id {frame_id!r} does not match expected frame {expected_frame!r}')


def check_count(kind: str, count: int, max_points: Optional[int]) -> None:
    """Refuse more than `max_points` points (None: any number)."""
    if max_points is not None and count > max_points:
        raise InputError(f'{kind} has {count} points, more than max_points={max_points}')


def check_finite_rows(kind: str, what: str, values: NDArray[np.float64]) -> None:
    """Refuse NaN or inf, naming how many rows and the first."""
    bad = ~np.isfinite(values)
    if bad.ndim > 1:
        bad = bad.any(axis=1)
    if bad.any():
        first = int(np.argmax(bad))
        raise InputError(
            f'{kind} has {int(bad.sum())} non-finite {what} (first at index {first}: '
            f'{values[first].tolist()})')


def check_positive(kind: str, intensities: NDArray[np.float64]) -> None:
    """Refuse intensities F <= 0, naming how many and the first."""
    bad = intensities <= 0.0
    if bad.any():
        first = int(np.argmax(bad))
        raise InputError(
            f'{kind} has {int(bad.sum())} non-positive intensities (first at index {first}: '
            f'{float(intensities[first])!r})')


def as_points(name: str, points: ArrayLike) -> NDArray[np.float64]:
    """Return `points` as an (n, 3) float64 array, refusing other shapes and NaN/inf."""
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f'{name} must have shape (n, 3), got {arr.shape}')
    check_finite_rows(name, 'points', arr)
    return arr


def as_edges(name: str, edges: ArrayLike, n_vertices: int) -> NDArray[np.intp]:
    """Return `edges` as (k, 2) vertex indices, refusing other shapes and bad indices."""
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
