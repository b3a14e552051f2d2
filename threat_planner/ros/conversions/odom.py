"""The vehicle's state from nav_msgs/Odometry: where it is and the way it flies.

Per REP-105 the pose is in ``header.frame_id`` (which must be parameter ``frame_id``) and
the twist in ``child_frame_id``, the body frame: the velocity is turned into ``frame_id``
by the pose's orientation. A twist whose ``child_frame_id`` is ``header.frame_id`` itself
is taken as given in that frame. The heading is the velocity's direction; below
:data:`MIN_SPEED_MPS` (hovering, or a vehicle not yet moving) it is the body x axis (the
nose) of the orientation. Every number read must be finite (the covariances are not
read), and the orientation must be a non-zero quaternion (it is normalised).
"""

from dataclasses import dataclass

from nav_msgs.msg import Odometry
import numpy as np
from numpy.typing import NDArray

from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import stamp_to_ns

__all__ = ['MIN_SPEED_MPS', 'Vehicle', 'rotate', 'vehicle_from_odometry']

#: Below this speed the heading is the nose's direction, not the velocity's [m/s].
MIN_SPEED_MPS = 0.5


@dataclass(frozen=True)
class Vehicle:
    """The vehicle as one odometry message gives it.

    Attributes
    ----------
    position : NDArray
        (3,) [m] in ``frame_id``.
    heading : NDArray
        (3,) unit direction it flies in ``frame_id``.
    speed : float
        Its speed [m/s].
    from_velocity : bool
        Whether the heading is the velocity's (else the nose's: slower than
        :data:`MIN_SPEED_MPS`).
    stamp_ns : int
        The message's stamp [ns].
    received_ns : int
        When the node took it, on the node's clock [ns] (0 until the node sets it).

    """

    position: NDArray
    heading: NDArray
    speed: float
    from_velocity: bool
    stamp_ns: int
    received_ns: int = 0


def rotate(q: NDArray, v: NDArray) -> NDArray:
    """Turn vector `v` (3,) by the unit quaternion `q` (x, y, z, w)."""
    u, w = q[:3], q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def _finite(name: str, values: list[float]) -> NDArray:
    arr = np.array(values, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise InputError(f'odom {name}: not finite: {arr.tolist()}')
    return arr


def vehicle_from_odometry(msg: Odometry, expected_frame: str) -> Vehicle:
    """Read the vehicle's position and heading from an Odometry (module docstring).

    Parameters
    ----------
    msg : nav_msgs.msg.Odometry
        The vehicle's odometry.
    expected_frame : str
        Frame the pose must be in; compared with ``header.frame_id``.

    Returns
    -------
    Vehicle

    Raises
    ------
    InputError
        Naming the field: ``header.frame_id`` other than `expected_frame`, a non-finite
        position, orientation, linear or angular velocity, a zero quaternion.

    """
    if msg.header.frame_id != expected_frame:
        raise InputError(f'odom header.frame_id: {msg.header.frame_id!r} is not frame_id '
                         f'{expected_frame!r}')
    pose, twist = msg.pose.pose, msg.twist.twist
    p = pose.position
    position = _finite('pose.pose.position', [p.x, p.y, p.z])
    o = pose.orientation
    q = _finite('pose.pose.orientation', [o.x, o.y, o.z, o.w])
    n = float(np.linalg.norm(q))
    if n < 1e-9:
        raise InputError(f'odom pose.pose.orientation: not a rotation: {q.tolist()}')
    q = q / n
    v = twist.linear
    velocity = _finite('twist.twist.linear', [v.x, v.y, v.z])
    a = twist.angular
    _finite('twist.twist.angular', [a.x, a.y, a.z])
    if msg.child_frame_id != msg.header.frame_id:
        velocity = rotate(q, velocity)
    speed = float(np.linalg.norm(velocity))
    moving = speed >= MIN_SPEED_MPS
    heading = velocity / speed if moving else rotate(q, np.array([1.0, 0.0, 0.0]))
    return Vehicle(position, heading / np.linalg.norm(heading), speed, moving,
                   stamp_to_ns(msg.header.stamp))
