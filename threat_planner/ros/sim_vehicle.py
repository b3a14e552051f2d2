"""ROS 2 node ``sim_vehicle``: a simulated UAV that flies the planner's path, on topics.

Run as ``sim_vehicle --ros-args -p start:=[x,y,z] -p start_heading:=[yaw,pitch]``. It
flies the point mass of ``threat-planner fly`` (:class:`threat_planner.flight.vehicle.
PointMass`, at ``speed_mps`` with turn radius ``min_turn_radius_m`` and flight-path angle
within ``max_climb_deg`` / ``max_dive_deg``) the way the ``fly`` loop does
(:func:`threat_planner.flight.follow.follow_step`: aim LOOK turn radii ahead on the path).

* ``path`` (nav_msgs/Path, subscribed latched like the planner publishes it): the path
  followed. A new path replaces the old one from where the vehicle is: it joins the new
  path at its point nearest the vehicle (the first time, if the path comes back by it:
  :func:`threat_planner.flight.follow.join`). A path in another frame than
  ``frame_id``, with a NaN or with fewer than two distinct points is refused (a warning).
  Until the first path the vehicle flies straight on from ``start`` along
  ``start_heading`` (yaw about +z from +x, pitch nose-up, in degrees); past a path's end
  it flies on along its last segment.
* ``odom`` (nav_msgs/Odometry) at ``rate_hz``: every tick advances the simulation by
  exactly 1 / ``rate_hz`` (stamped with the node's clock). The pose is in ``frame_id``,
  the orientation is the heading (zero roll), the twist is in the body frame
  ``base_link`` per REP-105: ``[speed, 0, 0]``.

The defaults of the speed and the limits are the planner's (``config/planner.yaml``), so
the vehicle flies what the planner plans. Every parameter may be set at run time and is
checked first (a bad value is refused with the reason); setting ``start`` or
``start_heading`` puts the vehicle there and drops its path.
"""

from __future__ import annotations

import math
from typing import Optional

from nav_msgs.msg import Odometry, Path
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import (FloatingPointRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
from rclpy.node import Node

from threat_planner.core.flight.reference import ReferencePath
from threat_planner.core.inputs.settings import NODE_SETTINGS
from threat_planner.core.trajectory import quaternions, yaw_pitch
from threat_planner.errors import InputError
from threat_planner.flight.follow import follow_step, join
from threat_planner.flight.vehicle import PointMass
from threat_planner.ros.conversions import path_from_msg
from threat_planner.ros.interface import LATCHED, POSE_INPUT
from threat_planner.ros.parameters import descriptor
from threat_planner.ros.process import run_node

__all__ = ['CHILD_FRAME', 'NODE_NAME', 'SimVehicle', 'check_parameter', 'heading_of', 'main']

NODE_NAME = 'sim_vehicle'
#: The body frame of the twist (REP-105).
CHILD_FRAME = 'base_link'
#: The planner's settings the vehicle shares: defaults and ranges from the settings table.
SHARED = ('frame_id', 'speed_mps', 'min_turn_radius_m', 'max_climb_deg', 'max_dive_deg')
_HELP = {
    'frame_id': 'Frame of the path taken and of the odometry published',
    'speed_mps': 'Speed the vehicle flies at (the planner\'s cruise speed)',
    'min_turn_radius_m': 'Tightest turn of the vehicle (0 = turns on the spot)',
    'max_climb_deg': 'Steepest climb of the vehicle (90 = none)',
    'max_dive_deg': 'Steepest dive of the vehicle (90 = none)',
}
#: Odometry QoS: reliable (a best-effort subscriber, as the planner's odom input is,
#: takes a reliable publisher too), volatile, depth 10.
ODOM_QOS = POSE_INPUT


def heading_of(yaw_pitch_deg) -> NDArray:
    """Return the unit direction (3,) of ``[yaw, pitch]`` in degrees."""
    yaw, pitch = (math.radians(float(v)) for v in yaw_pitch_deg)
    return np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                     math.sin(pitch)])


def _numbers(name: str, value: object, count: int, what: str) -> list[float]:
    if isinstance(value, (str, bytes, bool)) or not hasattr(value, '__len__') \
            or len(value) != count:
        raise InputError(f'{name}: expected {what}, got {value!r}')
    out = [float(v) for v in value]
    if not all(math.isfinite(v) for v in out):
        raise InputError(f'{name}: must be finite, got {out}')
    return out


def check_parameter(name: str, value: object) -> None:
    """Raise InputError naming parameter `name` and `value` unless the vehicle takes it."""
    if name in SHARED:
        NODE_SETTINGS[name].check(value)
    elif name == 'rate_hz':
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not (math.isfinite(value) and 0.0 < value <= 1000.0):
            raise InputError(f'rate_hz: must be finite and 0 < rate_hz <= 1000, got {value!r}')
    elif name == 'start':
        _numbers('start', value, 3, '[x, y, z]')
    elif name == 'start_heading':
        _, pitch = _numbers('start_heading', value, 2, '[yaw, pitch] [deg]')
        if abs(pitch) > 90.0:
            raise InputError(f'start_heading: pitch must be within -90..90 deg, got {pitch:g}')


def _descriptor(name: str, description: str = '', **range_) -> ParameterDescriptor:
    if name in SHARED:
        desc = descriptor(name)
        desc.description = f'{_HELP[name]}; default the planner\'s ({desc.description})'
        return desc
    desc = ParameterDescriptor(name=name, description=description, dynamic_typing=False)
    if 'lo' in range_:
        desc.type = ParameterType.PARAMETER_DOUBLE
        desc.floating_point_range = [FloatingPointRange(from_value=range_['lo'],
                                                        to_value=range_['hi'], step=0.0)]
    else:
        desc.type = ParameterType.PARAMETER_DOUBLE_ARRAY
    return desc


class SimVehicle(Node):
    """The simulated vehicle; see the module docstring.

    Raises
    ------
    InputError
        If a parameter is out of range (naming it and its value).

    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for name in SHARED:
            self.declare_parameter(name, NODE_SETTINGS[name].default, _descriptor(name))
        self.declare_parameter('rate_hz', 20.0, _descriptor(
            'rate_hz', 'Odometry rate [Hz]; each message is 1 / rate_hz of flight later',
            lo=0.0, hi=1000.0))
        self.declare_parameter('start', list(NODE_SETTINGS['start'].default), _descriptor(
            'start', "Where the vehicle starts [x, y, z] [m] (default the planner's start)"))
        self.declare_parameter('start_heading', [0.0, 0.0], _descriptor(
            'start_heading', 'The way it flies at the start: [yaw, pitch] [deg], yaw about '
                             '+z from +x, pitch nose-up'))
        values = {name: self.get_parameter(name).value
                  for name in SHARED + ('rate_hz', 'start', 'start_heading')}
        for name, value in values.items():
            check_parameter(name, value)
        self._values = values
        self._ref: Optional[ReferencePath] = None
        self._s = 0.0
        self._at_end = False
        self._vehicle = self._start_state()
        self._timer = None
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.create_subscription(Path, 'path', self._on_path, LATCHED)
        self._pub = self.create_publisher(Odometry, 'odom', ODOM_QOS)
        self._restart_timer()
        self.get_logger().info(
            f'flying from {self._vehicle.position.tolist()} heading '
            f'{self._values["start_heading"]} deg at {self._vehicle.speed:g} m/s, odom at '
            f'{self._values["rate_hz"]:g} Hz in {self._values["frame_id"]}')

    # -- parameters ----------------------------------------------------------------------
    def _start_state(self) -> PointMass:
        v = self._values
        return PointMass(np.array(v['start'], float), heading_of(v['start_heading']),
                         float(v['speed_mps']), float(v['min_turn_radius_m']),
                         float(v['max_climb_deg']), float(v['max_dive_deg']))

    def _check_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name in self._values:
                try:
                    check_parameter(p.name, p.value)
                except InputError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params) -> None:
        changed = {p.name for p in params if p.name in self._values}
        for p in params:
            if p.name in changed:
                self._values[p.name] = p.value
        v, car = self._values, self._vehicle
        if changed & {'start', 'start_heading'}:
            self._vehicle, self._ref, self._at_end = self._start_state(), None, False
        else:
            car.speed = float(v['speed_mps'])
            car.min_turn_radius_m = float(v['min_turn_radius_m'])
            car.max_climb_deg = float(v['max_climb_deg'])
            car.max_dive_deg = float(v['max_dive_deg'])
        if 'rate_hz' in changed:
            self._restart_timer()

    def _restart_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._dt = 1.0 / float(self._values['rate_hz'])
        self._timer = self.create_timer(self._dt, self._tick)

    # -- flight ----------------------------------------------------------------------------
    def _on_path(self, msg: Path) -> None:
        frame = self._values['frame_id']
        points = path_from_msg(msg)
        if msg.header.frame_id != frame:
            reason = f'header.frame_id {msg.header.frame_id!r} is not frame_id {frame!r}'
        elif not np.isfinite(points).all():
            reason = 'poses: not finite'
        elif len(points) < 2 or ReferencePath(points).length <= 0.0:
            reason = f'poses: fewer than 2 distinct points ({len(points)} poses)'
        else:
            reason = ''
        if reason:
            self.get_logger().warning(f'path refused, still flying the last one: {reason}')
            return
        self._ref = ReferencePath(points)
        self._s = join(self._ref, self._vehicle.position)
        self._at_end = False
        self.get_logger().info(f'new path: {len(points)} poses, {self._ref.length:.1f} m, '
                               f'joined at {self._s:.1f} m')

    def _tick(self) -> None:
        car = self._vehicle
        if self._ref is None:
            car.step(car.position + car.heading * max(car.speed * self._dt, 1.0), self._dt)
        else:
            self._s, _ = follow_step(car, self._ref, self._s, self._dt)
            if not self._at_end and self._s >= self._ref.length:
                self._at_end = True
                self.get_logger().info('end of the path: flying on along its last segment')
        self._pub.publish(self._odometry())

    def _odometry(self) -> Odometry:
        car = self._vehicle
        msg = Odometry()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self._values['frame_id']
        msg.child_frame_id = CHILD_FRAME
        p = msg.pose.pose.position
        p.x, p.y, p.z = (float(c) for c in car.position)
        q = quaternions(yaw_pitch(car.heading[None]))[0]
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = (float(c) for c in q)
        msg.twist.twist.linear.x = float(car.speed)
        return msg


def main(args: Optional[list[str]] = None) -> int:
    """Run the simulated vehicle until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command line (``--ros-args -p start:=[x,y,z] ...``); ``sys.argv`` if None.

    Returns
    -------
    int
        0 after a clean shutdown, 1 if a parameter was refused.

    """
    return run_node(SimVehicle, NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())
