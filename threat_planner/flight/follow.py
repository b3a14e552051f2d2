"""One step of the simulated vehicle along its reference path, shared by every simulator.

The ``fly`` loop (:mod:`.fly`) and the ``sim_vehicle`` node
(:mod:`threat_planner.ros.sim_vehicle`) both fly a :class:`~.vehicle.PointMass` with
:func:`follow_step`: find where the vehicle is on the path (its arc length, searched near
the last one), then steer towards the point ``LOOK`` turn radii (and at least two steps)
ahead of it.
"""

from __future__ import annotations

import numpy as np

from threat_planner.core.flight.reference import ReferencePath
from threat_planner.flight.vehicle import PointMass

__all__ = ['JOIN_SLACK_M', 'LOOK', 'follow_step', 'join']

#: The vehicle aims this many turn radii ahead on the path (and at least two steps):
#: at 1.0, 4 of 8 bench flights missed the goal (tracking 38-46 m off after a miss), at
#: 0.5 none (tracking within 0.9 m).
LOOK = 0.5
#: A new path is joined at its first point this close to the nearest [m] (:func:`join`).
JOIN_SLACK_M = 1.0


def follow_step(vehicle: PointMass, ref: ReferencePath, s_now: float,
                dt: float) -> tuple[float, float]:
    """Fly `vehicle` one step of `dt` [s] along `ref` from arc length `s_now` [m].

    Parameters
    ----------
    vehicle : PointMass
        Moved in place; its speed and turn radius set the search and the look-ahead.
    ref : ReferencePath
        The path followed.
    s_now : float
        The vehicle's arc length on `ref` after the previous step [m].
    dt : float
        Step [s].

    Returns
    -------
    s_now : float
        The arc length the vehicle stood at when the step began [m].
    off : float
        Its distance from the path after the step [m].

    """
    reach = 3 * vehicle.speed * dt + 1.0
    s_now = ref.project(vehicle.position, max(s_now - 1.0, 0.0), s_now + reach)
    look = max(LOOK * vehicle.min_turn_radius_m, 2 * vehicle.speed * dt)
    vehicle.step(ref.ahead(s_now + look), dt)
    s = ref.project(vehicle.position, max(s_now - 1.0, 0.0), s_now + reach)
    return s_now, float(np.linalg.norm(ref.at(s) - vehicle.position))


def join(ref: ReferencePath, p: np.ndarray, slack: float = JOIN_SLACK_M) -> float:
    """Return the arc length at which a vehicle at `p` (3,) [m] joins a new path `ref`.

    The nearest point of `ref` to `p`, except that a path passing near `p` twice (a loop
    planned from the vehicle that comes back by it) is joined the first time: at the
    first segment whose nearest point is within `slack` [m] of the nearest of all.
    """
    a, b = ref.points[:-1], ref.points[1:]
    d = b - a
    l2 = np.maximum(np.einsum('ij,ij->i', d, d), 1e-300)
    u = np.clip(np.einsum('ij,ij->i', p - a, d) / l2, 0.0, 1.0)
    dist = np.linalg.norm(a + u[:, None] * d - p, axis=1)
    k = int(np.flatnonzero(dist <= dist.min() + slack)[0])
    return float(ref.s[k] + u[k] * np.sqrt(l2[k]))
