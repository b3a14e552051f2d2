"""Threat positions as geometry_msgs/PoseArray; start and goal as PoseStamped."""

from typing import Optional, Tuple

from geometry_msgs.msg import PoseArray, PoseStamped
import numpy as np
from numpy.typing import NDArray

from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import check_count, check_finite_rows, check_frame


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
    check_frame('PoseArray', msg.header.frame_id, expected_frame)
    intensity = float(default_intensity)
    if not np.isfinite(intensity) or intensity <= 0.0:
        raise InputError(f'default_intensity must be finite and > 0, got {intensity!r}')
    check_count('PoseArray', len(msg.poses), max_points)
    positions = np.array([(p.position.x, p.position.y, p.position.z) for p in msg.poses],
                         dtype=np.float64).reshape(-1, 3)
    check_finite_rows('PoseArray', 'positions', positions)
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
    check_frame(name, msg.header.frame_id, expected_frame)
    p = msg.pose.position
    point = np.array([p.x, p.y, p.z], dtype=np.float64)
    if not np.isfinite(point).all():
        raise InputError(f'{name} position must be finite, got {point.tolist()}')
    return point
