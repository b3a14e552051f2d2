"""
ROS 2 node ``threat_publisher``: publishes a scenario file for the planner node.

Run as ``threat_publisher --ros-args -p scenario:=FILE``. It publishes the scenario's
threats (``threats``, sensor_msgs/PointCloud2 x, y, z, intensity; or ``threat_poses``,
geometry_msgs/PoseArray, with ``use_pose_array:=true``), ``start`` and ``goal_pose``
(geometry_msgs/PoseStamped), all reliable and transient local (latched, depth 1).

* ``rate`` = 0 (default): the picture is published once and stays latched.
* ``rate`` > 0: the picture is published at ``rate`` Hz, stamped with the publish time; with
  ``drift`` > 0 [m/s] every threat moves between publications, deterministically for a given
  ``seed``: ``drift_mode`` ``random_walk`` steps each threat ``drift / rate`` metres in a
  random direction (reflected at the bounds), ``sinusoid`` swings each threat along a random
  axis with period ``drift_period`` [s] and peak speed ``drift``.

* ``events_file`` (default '': none): an events file (the layout of ``threat-planner fly
  --events``, :mod:`threat_planner.flight.events`) played on the node's clock from its
  start: at each event's time the picture is republished as it is then, with every
  threat where it is at that time (a threat with a velocity, the scenario's or an
  event's, is republished at 2 Hz as it moves, and a cloud in which one moves carries
  every threat's ``vx vy vz``); a goal event publishes the new ``goal_pose``; an
  ``add_zone`` event publishes ``no_fly_zones`` (latched): the scenario's zones and every
  zone added so far, since a ``no_fly_zones`` message replaces the planner's zones. A bad
  events file is refused before anything is published: one line naming the field, exit
  code 2.

Start and goal are published at start-up and again whenever a new subscriber appears: a
planner subscribes to them volatile (so that RViz's pose tools work) and would otherwise
miss them if it starts after this node. Threats need no such help: the planner subscribes
to them transient local and gets the latched picture.
"""

from __future__ import annotations

import math
from typing import Optional

from geometry_msgs.msg import Pose, PoseArray, PoseStamped
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.errors import InputError
from threat_planner.flight.playback import Playback
from threat_planner.ros.conversions import pointcloud2_from_threats
from threat_planner.ros.conversions.airspace import zones_to_markers
from threat_planner.ros.process import run_node

__all__ = ['ThreatDrift', 'ThreatPublisher', 'main']

NODE_NAME = 'threat_publisher'
DRIFT_MODES = ('random_walk', 'sinusoid')
LATCHED = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=1)
# How often to look for new start/goal subscribers [s].
_MATCH_POLL_S = 0.2
#: How often events are looked for while an events file plays [s].
EVENT_POLL_S = 0.05
#: How often a moving threat is republished while an events file plays [s] (2 Hz).
MOVING_PERIOD_S = 0.5
#: main()'s exit code for a bad events file.
EXIT_BAD_EVENTS = 2


class _EventsFileError(InputError):
    """A bad events file (main() exits EXIT_BAD_EVENTS)."""


class ThreatDrift:
    """Deterministic threat motion: a reflected random walk or a per-threat sinusoid.

    Parameters
    ----------
    positions : NDArray
        Initial threat positions (N, 3) [m].
    lo, hi : NDArray
        Bounds the threats stay in (3,) [m].
    speed : float
        Step length per second (random walk) or peak speed (sinusoid) [m/s].
    mode : str
        'random_walk' or 'sinusoid'.
    period : float
        Period of the sinusoid [s].
    seed : int
        Seed of the random directions and phases.

    """

    def __init__(self, positions: NDArray, lo: NDArray, hi: NDArray, speed: float,
                 mode: str = 'random_walk', period: float = 20.0, seed: int = 0) -> None:
        if mode not in DRIFT_MODES:
            raise InputError(f'drift_mode: must be one of {", ".join(DRIFT_MODES)}, '
                             f'got {mode!r}')
        if not (math.isfinite(speed) and speed >= 0.0):
            raise InputError(f'drift: must be finite and >= 0, got {speed!r}')
        if not (math.isfinite(period) and period > 0.0):
            raise InputError(f'drift_period: must be finite and > 0, got {period!r}')
        self._p0 = np.array(positions, dtype=float).reshape(-1, 3)
        self._p = self._p0.copy()
        self._lo = np.asarray(lo, dtype=float)
        self._hi = np.asarray(hi, dtype=float)
        self._speed = float(speed)
        self._mode = mode
        self._rng = np.random.default_rng(seed)
        n = len(self._p0)
        self._axes = _unit_rows(self._rng.normal(size=(n, 3)))
        self._phases = self._rng.uniform(0.0, 2.0 * math.pi, size=n)
        self._omega = 2.0 * math.pi / period

    def at(self, t: float, dt: float) -> NDArray:
        """Positions at time `t` [s], `dt` [s] after the previous call.

        The random walk depends on the sequence of calls (one step per call); the sinusoid
        only on `t`.
        """
        if self._speed == 0.0 or len(self._p0) == 0:
            return self._p.copy()
        if self._mode == 'sinusoid':
            amplitude = self._speed / self._omega
            offset = amplitude * np.sin(self._omega * t + self._phases)
            self._p = _reflect(self._p0 + offset[:, None] * self._axes, self._lo, self._hi)
        else:
            steps = _unit_rows(self._rng.normal(size=self._p.shape)) * (self._speed * dt)
            self._p = _reflect(self._p + steps, self._lo, self._hi)
        return self._p.copy()


def _unit_rows(v: NDArray) -> NDArray:
    norms = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(norms > 0.0, norms, 1.0)


def _reflect(p: NDArray, lo: NDArray, hi: NDArray) -> NDArray:
    """Mirror points that left [lo, hi] back inside (a threat bounces off the bounds)."""
    span = hi - lo
    q = np.mod(p - lo, 2.0 * span)
    return lo + np.where(q > span, 2.0 * span - q, q)


class ThreatPublisher(Node):
    """Publishes one scenario; see the module docstring.

    Raises
    ------
    InputError
        If parameter ``scenario`` is empty, the file is bad, or a parameter is out of range.

    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.declare_parameter('scenario', '', ParameterDescriptor(
            description='Scenario YAML file (bounds, start, goal, threats)'))
        self.declare_parameter('rate', 0.0, ParameterDescriptor(
            description='Publication rate [Hz]; 0 publishes once, latched',
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1000.0)]))
        self.declare_parameter('drift', 0.0, ParameterDescriptor(
            description='Threat speed [m/s] between publications (needs rate > 0)',
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1.0e6)]))
        self.declare_parameter('drift_mode', 'random_walk', ParameterDescriptor(
            description="'random_walk' or 'sinusoid'",
            additional_constraints="one of 'random_walk', 'sinusoid'"))
        self.declare_parameter('drift_period', 20.0, ParameterDescriptor(
            description='Period of the sinusoidal drift [s]',
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1.0e6)]))
        self.declare_parameter('seed', 0, ParameterDescriptor(
            description='Seed of the drift'))
        self.declare_parameter('use_pose_array', False, ParameterDescriptor(
            description='Publish threats as a PoseArray on threat_poses (intensities are '
                        "then the planner's default_intensity)"))
        self.declare_parameter('frame_id', '', ParameterDescriptor(
            description="Frame of the messages; '' = the scenario's frame_id"))
        self.declare_parameter('events_file', '', ParameterDescriptor(
            description="Events file played from the node's start (threat-planner fly "
                        "--events layout); '' = none"))
        self.declare_parameter('namespaces', [''], ParameterDescriptor(
            description="Publish to each of these namespaces (['/uav1', '/uav2']); "
                        "[''] = this node's own namespace"))

        path = self.get_parameter('scenario').value
        if not path:
            raise InputError('scenario: give a scenario file with -p scenario:=FILE')
        self._scenario: Scenario = load_scenario(path)
        self._playback = self._load_events(self.get_parameter('events_file').value)
        self._t0, self._published_t = self.get_clock().now(), 0.0    # the events' clock
        self._frame = self.get_parameter('frame_id').value or self._scenario.frame_id
        self._rate = float(self.get_parameter('rate').value)
        self._use_poses = bool(self.get_parameter('use_pose_array').value)
        drift = float(self.get_parameter('drift').value)
        box = self._scenario.box
        self._drift = ThreatDrift(self._scenario.threats.positions, box.lo, box.hi, drift,
                                  self.get_parameter('drift_mode').value,
                                  float(self.get_parameter('drift_period').value),
                                  int(self.get_parameter('seed').value))
        if drift > 0.0 and self._rate == 0.0:
            self.get_logger().warning('drift is ignored with rate 0 (published once)')
        if drift > 0.0 and self._playback is not None:
            self.get_logger().warning('drift is ignored with an events file (it moves the '
                                      'threats)')
        self._tick = 0

        # One publisher set per namespace: a fleet of planners fed from one scenario.
        prefixes = [ns.rstrip('/') + '/' if ns else ''
                    for ns in self.get_parameter('namespaces').value]
        self._pubs_threats = [
            self.create_publisher(PoseArray, f'{p}threat_poses', LATCHED) if self._use_poses
            else self.create_publisher(PointCloud2, f'{p}threats', LATCHED) for p in prefixes]
        self._pub_threats = self._pubs_threats[0]
        self._pose_pubs = []
        for p in prefixes:
            self._pose_pubs.append(('start', self.create_publisher(
                PoseStamped, f'{p}start', LATCHED), self._scenario.start))
            self._pose_pubs.append(('goal', self.create_publisher(
                PoseStamped, f'{p}goal_pose', LATCHED), self._scenario.goal))
        self._matched = {id(pub): 0 for _, pub, _ in self._pose_pubs}
        # Zones only where the events add some: a planner's own zones stay its own.
        self._zone_pubs = [] if self._playback is None or not any(
            e.kind == 'add_zone' for e in self._playback.events) else [
            self.create_publisher(MarkerArray, f'{p}no_fly_zones', LATCHED) for p in prefixes]

        for _, pub, xyz in self._pose_pubs:
            self._publish_pose(pub, xyz)
        self._publish_threats()
        self.create_timer(_MATCH_POLL_S, self._republish_to_new_subscribers)
        if self._rate > 0.0:
            self.create_timer(1.0 / self._rate, self._publish_threats)
        if self._playback is not None:
            self.create_timer(EVENT_POLL_S, self._play)
        self.get_logger().info(
            f'{self._scenario.name}: {len(self._scenario.threats)} threats on '
            f'{", ".join(p.topic_name for p in self._pubs_threats)} in frame {self._frame}, '
            + (f'{self._rate:g} Hz, drift {drift:g} m/s' if self._rate > 0.0
               else 'published once (latched)'))

    def _load_events(self, path: str) -> Playback | None:
        if not path:
            return None
        try:
            playback = Playback.from_file(self._scenario, path)
        except InputError as exc:
            raise _EventsFileError(f'events_file {path}: {exc}') from None
        self.get_logger().info(f'events_file {path}: {len(playback.events)} events')
        return playback

    def _elapsed(self) -> float:
        return (self.get_clock().now() - self._t0).nanoseconds * 1e-9

    def _play(self) -> None:
        """Apply the events due now; republish what they changed, and moving threats."""
        t = self._elapsed()
        changed = False
        for event, goal in self._playback.due(t):
            self.get_logger().info(f'event: {event.describe()}')
            if goal is not None:
                self._pose_pubs = [(kind, pub, goal if kind == 'goal' else xyz)
                                   for kind, pub, xyz in self._pose_pubs]
                for kind, pub, xyz in self._pose_pubs:
                    if kind == 'goal':
                        self._publish_pose(pub, xyz)
            elif event.kind == 'add_zone':
                self._publish_zones()
            else:
                changed = True
        if changed or (self._playback.moving(t) and t - self._published_t >= MOVING_PERIOD_S):
            self._publish_threats()

    def _publish_zones(self) -> None:
        """Publish the scenario's zones and the events' so far on ``no_fly_zones``."""
        air = self._scenario.airspace
        zones = (tuple(air.zones) if air is not None else ()) + tuple(self._playback.zones)
        msg = zones_to_markers(zones, self._frame, self._stamp())
        for pub in self._zone_pubs:
            pub.publish(msg)

    def _picture(self) -> tuple[NDArray, NDArray, NDArray | None]:
        """Return the threats to publish: positions (N, 3), intensities (N,), velocities.

        The velocities (N, 3) [m/s] are those of an events file's picture in which a
        threat moves (the cloud's ``vx vy vz``), else None (a still picture).
        """
        if self._playback is not None:
            t = self._elapsed()
            self._published_t = t
            snap = self._playback.picture(t)
            moving = bool(np.any(snap.velocities != 0.0))
            return (snap.field.positions, snap.field.intensities,
                    snap.velocities if moving else None)
        dt = 1.0 / self._rate if self._rate > 0.0 else 0.0
        positions = self._drift.at(self._tick * dt, dt if self._tick else 0.0)
        self._tick += 1
        return positions, self._scenario.threats.intensities, None

    def _stamp(self):
        return self.get_clock().now().to_msg()

    def _publish_pose(self, publisher, xyz: NDArray) -> None:
        msg = PoseStamped()
        msg.header.frame_id = self._frame
        msg.header.stamp = self._stamp()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (
            float(v) for v in xyz)
        msg.pose.orientation.w = 1.0
        publisher.publish(msg)

    def _publish_threats(self) -> None:
        positions, intensities, velocities = self._picture()
        stamp = self._stamp()
        if self._use_poses:
            msg = PoseArray()
            msg.header.frame_id = self._frame
            msg.header.stamp = stamp
            msg.poses = [Pose() for _ in range(len(positions))]
            for pose, (x, y, z) in zip(msg.poses, positions.tolist()):
                pose.position.x, pose.position.y, pose.position.z = x, y, z
                pose.orientation.w = 1.0
        else:
            msg = pointcloud2_from_threats(positions, intensities, self._frame, stamp,
                                           velocities)
        for pub in self._pubs_threats:
            pub.publish(msg)

    def _republish_to_new_subscribers(self) -> None:
        for _, pub, xyz in self._pose_pubs:
            count = pub.get_subscription_count()
            if count > self._matched[id(pub)]:
                self._publish_pose(pub, xyz)
            self._matched[id(pub)] = count


def main(args: Optional[list[str]] = None) -> int:
    """Run the publisher until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command line (``--ros-args -p scenario:=FILE ...``); ``sys.argv`` if None.

    Returns
    -------
    int
        0 after a clean shutdown, 1 if the scenario or a parameter was refused,
        EXIT_BAD_EVENTS (2) if the events file was.

    """
    refused = []

    def factory() -> ThreatPublisher:
        try:
            return ThreatPublisher()
        except _EventsFileError:
            refused.append(True)
            raise
    code = run_node(factory, NODE_NAME, args)
    return EXIT_BAD_EVENTS if code == 1 and refused else code


if __name__ == '__main__':
    raise SystemExit(main())
