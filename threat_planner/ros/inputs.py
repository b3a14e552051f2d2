"""How an input becomes planner state: one place, used by the node and by replay.

The node holds an :class:`InputState`; every input (a threat picture, a start, a goal, a
set of parameter changes) goes through :func:`accept`, which returns the next state or
raises InputError with the reason the node logs and publishes. Replay rebuilds the node's
state from a recording with the same function, so a replayed plan starts from exactly
what the node planned from.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping, Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.planner import check_endpoints
from threat_planner.core.threats import ThreatField
from threat_planner.errors import InputError
from threat_planner.ros.conversions import (point_from_pose_stamped, threats_from_pointcloud2,
                                            threats_from_pose_array)
from threat_planner.ros.parameters import NodeSettings, settings_from_parameters

__all__ = ['INPUT_KINDS', 'InputState', 'NO_THREATS', 'accept']

NO_THREATS = ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0))
#: What :func:`accept` takes: the node's input topics and ``'parameters'``.
INPUT_KINDS = ('threats', 'threat_poses', 'start', 'goal_pose', 'parameters')


@dataclass(frozen=True)
class InputState:
    """What the node holds: parameters, threat picture, start and goal.

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

    """

    values: Mapping[str, object]
    settings: NodeSettings
    threats: Optional[ThreatField]
    start: NDArray
    goal: NDArray

    @classmethod
    def from_parameters(cls, values: Mapping[str, object]) -> 'InputState':
        """Return the state of a node just started with these parameters.

        Raises
        ------
        InputError
            If the parameters are invalid or start or goal is outside the bounds.

        """
        settings = settings_from_parameters(values)
        check_endpoints(settings.start, settings.goal, settings.box, NO_THREATS)
        return cls(dict(values), settings, None, settings.start, settings.goal)

    @property
    def known_threats(self) -> ThreatField:
        """The threat picture, or an empty one."""
        return NO_THREATS if self.threats is None else self.threats


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
        if settings.frame_id != s.frame_id:
            # The picture was received in the old frame; relabelling it would put every
            # threat in the wrong place. It is dropped (the node says so) until a picture
            # in the new frame arrives.
            threats = None
        check_endpoints(start, goal, settings.box,
                        NO_THREATS if threats is None else threats)
        return replace(state, values=values, settings=settings, threats=threats,
                       start=start, goal=goal)
    if kind == 'start':
        start = point_from_pose_stamped(msg, s.frame_id, 'start')
        check_endpoints(start, state.goal, s.box, state.known_threats)
        return replace(state, start=start)
    if kind == 'goal_pose':
        goal = point_from_pose_stamped(msg, s.frame_id, 'goal_pose')
        check_endpoints(state.start, goal, s.box, state.known_threats)
        return replace(state, goal=goal)
    if kind == 'threats':
        count = int(msg.width) * int(msg.height)
        if count > s.max_threats:
            raise InputError(f'PointCloud2 has {count} threats, more than '
                             f'max_threats={s.max_threats}')
        positions, intensities = threats_from_pointcloud2(msg, s.frame_id)
    elif kind == 'threat_poses':
        if len(msg.poses) > s.max_threats:
            raise InputError(f'PoseArray has {len(msg.poses)} threats, more than '
                             f'max_threats={s.max_threats}')
        positions, intensities = threats_from_pose_array(msg, s.frame_id, s.default_intensity)
    else:
        raise ValueError(f'unknown input kind {kind!r}; expected one of {INPUT_KINDS}')
    threats = ThreatField.from_arrays(positions, intensities)
    check_endpoints(state.start, state.goal, s.box, threats)
    return replace(state, threats=threats)
