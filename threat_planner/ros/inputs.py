"""How an input becomes planner state: one place, used by the node and by replay.

The node holds an :class:`InputState`; every input (a threat picture, a start, a goal,
no-fly zones, a terrain height map, the vehicle's odometry, a set of parameter changes)
goes through :func:`accept`, which returns the next state or raises InputError with the
reason the node logs and publishes. Replay rebuilds the node's state from a recording with the same
function, so a replayed plan starts from exactly what the node planned from. Which of the
airspace inputs wins: :mod:`threat_planner.ros.airspace_input`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping, Optional, Sequence

from builtin_interfaces.msg import Time
import numpy as np
from numpy.typing import NDArray

from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.terrain import Terrain
from threat_planner.core.world.threats import check_endpoints, ThreatField
from threat_planner.core.world.zones import Zone
from threat_planner.errors import InputError
from threat_planner.ros.airspace_input import (airspace_of, check_airspace_endpoints,
                                               load_airspace_file)
from threat_planner.ros.conversions import (moving_threats_from_pointcloud2,
                                            point_from_navsatfix, point_from_pose_stamped,
                                            stamp_to_ns, threats_from_pose_array, Vehicle,
                                            vehicle_from_odometry)
from threat_planner.ros.conversions.airspace import terrain_from_image, zones_from_markers
from threat_planner.ros.parameters import NodeSettings, settings_from_parameters

__all__ = ['INPUT_KINDS', 'InputState', 'NO_THREATS', 'accept', 'input_stamp']

NO_THREATS = ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0))
#: What :func:`accept` takes: the node's input topics and ``'parameters'``.
INPUT_KINDS = ('threats', 'threat_poses', 'start', 'goal_pose', 'no_fly_zones', 'terrain',
               'start_fix', 'goal_fix', 'odom', 'parameters')
#: Parameters that describe the grid of a height map received on topic ``terrain``.
_TERRAIN_GRID = ('terrain_origin', 'terrain_resolution', 'terrain_clearance',
                 'terrain_masking')


@dataclass(frozen=True)
class InputState:
    """What the node holds: parameters, threat picture, start, goal and airspace.

    Attributes
    ----------
    values : Mapping[str, object]
        Every parameter's current value.
    settings : NodeSettings
        Those values, validated.
    threats : ThreatField or None
        The threat picture; None until one arrives.
    start, goal : NDArray
        Current start and goal (3,) [m].
    zones : tuple of Zone
        No-fly zones (from ``airspace_file`` or the latest ``no_fly_zones`` message).
    terrain : Terrain or None
        Terrain (from ``airspace_file`` or the latest ``terrain`` message).
    terrain_from_topic : bool
        Whether the terrain came from topic ``terrain`` (then the ``terrain_*``
        parameters set its grid).
    velocities : NDArray or None
        The threats' velocities (N, 3) [m/s] from a cloud's ``vx vy vz``; None for a
        still picture.
    threats_stamp_ns : int
        When the picture's positions hold: the cloud's stamp [ns] (0 = unstamped; the node
        puts its receipt time there).
    vehicle : Vehicle or None
        The vehicle's last accepted odometry; None until one arrives (and after a
        ``start`` message or a frame change).

    """

    values: Mapping[str, object]
    settings: NodeSettings
    threats: Optional[ThreatField]
    start: NDArray
    goal: NDArray
    zones: Sequence[Zone] = ()
    terrain: Optional[Terrain] = None
    terrain_from_topic: bool = False
    velocities: Optional[NDArray] = None
    threats_stamp_ns: int = 0
    vehicle: Optional[Vehicle] = None

    @classmethod
    def from_parameters(cls, values: Mapping[str, object]) -> 'InputState':
        """Return the state of a node just started with these parameters.

        Raises
        ------
        InputError
            If the parameters or the airspace file are invalid, or start or goal is
            outside the bounds, inside a zone or below the terrain floor.

        """
        settings = settings_from_parameters(values)
        check_endpoints(settings.start, settings.goal, settings.box, NO_THREATS)
        air = load_airspace_file(settings.airspace_file)
        check_airspace_endpoints(settings.start, settings.goal, air or None)
        return cls(dict(values), settings, None, settings.start, settings.goal,
                   air.zones, air.terrain)

    @property
    def known_threats(self) -> ThreatField:
        """The threat picture, or an empty one."""
        return NO_THREATS if self.threats is None else self.threats

    @property
    def airspace(self) -> Optional[Airspace]:
        """The zones and terrain to plan in, or None when there are none."""
        return airspace_of(self.zones, self.terrain)


def input_stamp(msg: object) -> Time:
    """Return an input message's stamp; a MarkerArray's is its first marker's (0 if none)."""
    header = getattr(msg, 'header', None)
    if header is not None:
        return header.stamp
    markers = getattr(msg, 'markers', None)
    return markers[0].header.stamp if markers else Time()


def accept(state: InputState, kind: str, msg: object) -> InputState:
    """Return the state after one input, as the node takes it.

    Parameters
    ----------
    state : InputState
        The state before.
    kind : str
        One of :data:`INPUT_KINDS`.
    msg : object
        The message; for ``'parameters'``, a mapping of changed names to values.

    Returns
    -------
    InputState
        The state after.

    Raises
    ------
    InputError
        The reason the input is refused (the state stays as it was); a message that
        cannot be read at all is refused as ``cannot read: <error>``.

    """
    try:
        return _accept(state, kind, msg)
    except InputError:
        raise
    except Exception as exc:  # noqa: B902 - no message may stop the node
        raise InputError(f'cannot read: {type(exc).__name__}: {exc}') from exc


def _accept(state: InputState, kind: str, msg) -> InputState:
    s = state.settings
    if kind == 'parameters':
        values = {**state.values, **msg}
        settings = settings_from_parameters(values)
        start = settings.start if 'start' in msg else state.start
        goal = settings.goal if 'goal' in msg else state.goal
        threats = state.threats
        vehicle = state.vehicle
        if settings.frame_id != s.frame_id:
            # The picture was received in the old frame; relabelling it would put every
            # threat in the wrong place. It is dropped (the node says so) until a picture
            # in the new frame arrives; so is the vehicle's odometry.
            threats = vehicle = None
        check_endpoints(start, goal, settings.box,
                        NO_THREATS if threats is None else threats)
        zones, terrain, from_topic = state.zones, state.terrain, state.terrain_from_topic
        if 'airspace_file' in msg or settings.frame_id != s.frame_id:
            # Zones and terrain received in the old frame are dropped like its threats;
            # the file's are in frame_id, whichever it is.
            air = load_airspace_file(settings.airspace_file)
            zones, terrain, from_topic = air.zones, air.terrain, False
        elif from_topic and terrain is not None and set(_TERRAIN_GRID) & set(msg):
            terrain = _topic_terrain(settings, terrain.heights)
        check_airspace_endpoints(start, goal, airspace_of(zones, terrain))
        return replace(state, values=values, settings=settings, threats=threats,
                       start=start, goal=goal, zones=zones, terrain=terrain,
                       terrain_from_topic=from_topic, vehicle=vehicle,
                       velocities=None if threats is None else state.velocities)
    if kind in ('start', 'start_fix'):
        # geo (issue 26): a NavSatFix is converted with parameter datum, then taken alike
        start = (point_from_pose_stamped(msg, s.frame_id, 'start') if kind == 'start'
                 else point_from_navsatfix(msg, s.datum, kind))
        check_endpoints(start, state.goal, s.box, state.known_threats)
        check_airspace_endpoints(start, state.goal, state.airspace)
        # A start given is where the next plan starts: the vehicle's state is dropped
        # until the next odometry.
        return replace(state, start=start, vehicle=None)
    if kind == 'odom':
        vehicle = vehicle_from_odometry(msg, s.frame_id)
        try:
            check_endpoints(vehicle.position, state.goal, s.box, state.known_threats)
            check_airspace_endpoints(vehicle.position, state.goal, state.airspace)
        except InputError as exc:
            raise InputError(f'odom pose.pose.position: {str(exc).replace("start: ", "")}'
                             ) from None
        return replace(state, vehicle=vehicle)
    if kind in ('goal_pose', 'goal_fix'):
        goal = (point_from_pose_stamped(msg, s.frame_id, 'goal_pose') if kind == 'goal_pose'
                else point_from_navsatfix(msg, s.datum, kind))
        check_endpoints(state.start, goal, s.box, state.known_threats)
        check_airspace_endpoints(state.start, goal, state.airspace)
        return replace(state, goal=goal)
    if kind == 'no_fly_zones':
        zones = zones_from_markers(msg, s.frame_id)
        check_airspace_endpoints(state.start, state.goal, airspace_of(zones, state.terrain))
        return replace(state, zones=zones)
    if kind == 'terrain':
        terrain = terrain_from_image(msg, s.frame_id, s.terrain_origin, s.terrain_resolution,
                                     s.terrain_clearance, s.terrain_masking)
        check_airspace_endpoints(state.start, state.goal, airspace_of(state.zones, terrain))
        return replace(state, terrain=terrain, terrain_from_topic=terrain is not None)
    if kind == 'threats':
        count = int(msg.width) * int(msg.height)
        if count > s.max_threats:
            raise InputError(f'PointCloud2 has {count} threats, more than '
                             f'max_threats={s.max_threats}')
        positions, intensities, velocities = moving_threats_from_pointcloud2(msg, s.frame_id)
    elif kind == 'threat_poses':
        if len(msg.poses) > s.max_threats:
            raise InputError(f'PoseArray has {len(msg.poses)} threats, more than '
                             f'max_threats={s.max_threats}')
        positions, intensities = threats_from_pose_array(msg, s.frame_id, s.default_intensity)
        velocities = None
    else:
        raise ValueError(f'unknown input kind {kind!r}; expected one of {INPUT_KINDS}')
    threats = ThreatField.from_arrays(positions, intensities)
    check_endpoints(state.start, state.goal, s.box, threats)
    return replace(state, threats=threats, velocities=velocities,
                   threats_stamp_ns=stamp_to_ns(msg.header.stamp))


def _topic_terrain(settings: NodeSettings, heights: NDArray) -> Terrain:
    return Terrain.from_arrays(settings.terrain_origin, settings.terrain_resolution, heights,
                               settings.terrain_clearance, settings.terrain_masking)
