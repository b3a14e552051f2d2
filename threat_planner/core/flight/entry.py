"""Leave the start along the vehicle's heading: the first turn keeps the turn radius.

A plan from a vehicle in flight must start in the direction it flies: its first segment
along the heading ``h`` (no turn at the start, which the fillet rule of
:mod:`threat_planner.core.optimise.limits` does not check), the turns after it within
the limits. :func:`enter` makes a plan so. It pursues the plan from the start within the
limits (:mod:`.turn_in`: flyable by construction) until it flies along it, then joins the
plan's own vertices. Where the plan cannot be joined (it climbs at the limit above the
pursuit, say) and a ``replan`` is given, the picture is planned again from where the
pursuit had turned and that plan pursued. Failing both, the least violating path is
returned, flagged infeasible. Where the plan already leaves along the heading it is
returned as it is.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.flight.turn_in import outside, pursue_plan
from threat_planner.core.world.threats import Box
from threat_planner.core.world.zones import Zone
from threat_planner.errors import InputError, ThreatPlannerError

__all__ = ['Entry', 'enter', 'unit_heading']

#: A plan already leaves along the heading when its first segment is within this [rad].
ALIGNED = 1e-9


@dataclass(frozen=True)
class Entry:
    """A path that leaves along the heading, and how it was made.

    Attributes
    ----------
    points : NDArray
        The path (M, 3) [m].
    changed : int
        Vertices moved (0: the plan already left along the heading).
    feasible : bool
        Whether the path meets the limits, stays in the box (when one is given) and
        leaves along the heading.
    turn_deg : float
        Angle between the heading and the plan's first segment before [deg].
    clear : bool
        Whether it keeps out of the zones it was to keep out of (False: no turn-in
        within the limits did, and this one goes through one).

    """

    points: NDArray
    changed: int
    feasible: bool
    turn_deg: float
    clear: bool = True


def unit_heading(value: ArrayLike, name: str = 'start_heading') -> NDArray:
    """Return a heading from a vector (3,) or from ``[yaw, pitch]`` [deg], as a unit vector.

    Raises
    ------
    InputError
        Naming `name` for a non-finite, zero or wrongly sized value.

    """
    v = np.asarray(value, float).reshape(-1)
    if not np.all(np.isfinite(v)) or len(v) not in (2, 3):
        raise InputError(f'{name}: expected [x, y, z] or [yaw_deg, pitch_deg], finite, got '
                         f'{v.tolist()}')
    if len(v) == 2:
        yaw, pitch = np.radians(v)
        v = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                      math.sin(pitch)])
    n = float(np.linalg.norm(v))
    if n == 0:
        raise InputError(f'{name}: a zero vector has no direction')
    return v / n


def enter(points: ArrayLike, heading: ArrayLike, box: Box | None, limits: FlightLimits,
          replan: Callable[[NDArray], NDArray] | None = None,
          zones: Sequence[Zone] = ()) -> Entry:
    """Return the plan `points` made to leave its start along `heading` (module docstring).

    Parameters
    ----------
    points : array_like
        A plan (M, 3) [m] from the start.
    heading : array_like
        Unit direction the vehicle flies at the start.
    box : Box, optional
        Bounds the path stays in.
    limits : FlightLimits
        The limits every turn and segment must meet.
    replan : callable, optional
        ``replan(point)`` plans the same picture from `point` to the goal, (K, 3) [m];
        used where the pursuit cannot join the plan (module docstring).
    zones : sequence of Zone
        Zones the turn-in keeps out of (the lethal spheres the plan was made around).

    Returns
    -------
    Entry

    """
    pts = np.array(points, float)
    h = np.asarray(heading, float) / np.linalg.norm(heading)
    first = pts[1] - pts[0]
    # atan2, not acos: acos loses half the digits near an angle of 0.
    turn = math.atan2(float(np.linalg.norm(np.cross(first, h))), float(first @ h))
    if turn <= ALIGNED or len(pts) < 3:
        ok = (turn <= ALIGNED and _inside(pts, box)
              and check_limits(pts, limits, _floor(box)).feasible)
        return Entry(pts, 0, ok, math.degrees(turn))
    if len(pts) < 4:   # one free vertex is too few to turn in: add vertices evenly
        pts = np.vstack([pts[:1], pts[0] + np.linspace(0, 1, 5)[1:-1, None] * (
            pts[1] - pts[0]), pts[1:]])
    # Within the limits first; only a turn-in that then enters a zone is sought again
    # among the ways round that keep out of the zones (a path that breaks the limits
    # would break them with the zones too, and the first pass is the common answer).
    got = _enter(pts, h, turn, box, limits, replan, ())
    if not got.feasible or outside(got.points, zones):
        return got
    clear = _enter(pts, h, turn, box, limits, replan, zones)
    if clear.feasible:
        return clear
    return Entry(got.points, got.changed, True, got.turn_deg, clear=False)


def _enter(pts: NDArray, h: NDArray, turn: float, box: Box | None, limits: FlightLimits,
           replan: Callable[[NDArray], NDArray] | None, zones: Sequence[Zone]) -> Entry:
    """Return :func:`enter`'s path for a plan not already along the heading."""
    floor = _floor(box)
    corners = None if box is None else (box.lo, box.hi)
    # A pursuit of the plan within the limits is flyable by construction (.turn_in).
    # SLSQP from it never ended lower within the limits (18 headings on a 20-threat
    # field: 0 of 18, at 30-900 ms each against 1-3 ms for the pursuit), so it is kept.
    got = pursue_plan(pts, h, limits, floor, corners, zones)
    if got.feasible:
        return Entry(got.path, len(got.path) - 1 - _tail_vertices(got.path, pts), True,
                     math.degrees(turn))
    best = got.path
    if replan is not None and got.turned is not None:
        # The plan cannot be joined (it climbs at the limit above the pursuit, say): plan
        # again from where the pursuit had turned, and pursue that plan from there.
        try:
            again = replan(got.turned[-1])
        except ThreatPlannerError:
            again = None
        if again is not None:
            rest = pursue_plan(again, got.turned_heading, limits, floor, corners, zones)
            # Without the joint vertex: the two steps either side of it are collinear,
            # and as one segment the turn after it keeps the share it had in `rest`.
            joined = np.vstack([got.turned[:-1], rest.path[1:]])
            if (_inside(joined, box) and outside(joined, zones)
                    and check_limits(joined, limits, floor).feasible):
                return Entry(joined, len(joined) - 1, True, math.degrees(turn))
            if _excess(joined, limits, floor, box) < _excess(best, limits, floor, box):
                best = joined
    # Neither joins within the limits: the least violating path, flagged. (An SLSQP on
    # the first vertices under the limits' constraints, the fallback before, ended
    # feasible on 1 of 8 such entries of 32 bench flights, at a median 158 ms a run.)
    return Entry(best, len(best) - 1 - _tail_vertices(best, pts), False, math.degrees(turn))


def _tail_vertices(path: NDArray, plan: NDArray) -> int:
    """Return how many of `path`'s last vertices are the plan's own, unchanged."""
    n = 0
    while n < min(len(path), len(plan)) and np.array_equal(path[-1 - n], plan[-1 - n]):
        n += 1
    return n


def _relative_excess(violations: dict[str, float], limits: FlightLimits) -> float:
    """Return the largest breach relative to its limit, as check_limits ranks them."""
    unit = {'climb_deg': max(limits.max_climb_deg, 1.0),
            'dive_deg': max(limits.max_dive_deg, 1.0),
            'turn_radius_m': limits.min_turn_radius_m,
            'altitude_m': max(limits.min_altitude_m, 1.0)}
    return max((v / unit[k] for k, v in violations.items()), default=0.0)


def _excess(path: NDArray, limits: FlightLimits, floor: float, box: Box | None) -> float:
    """Return how far `path` breaks the limits (relative) or leaves the box (in radii)."""
    out = _relative_excess(check_limits(path, limits, floor).violations, limits)
    if box is not None:
        gone = max(float(np.max(box.lo - path)), float(np.max(path - box.hi)), 0.0)
        out = max(out, gone / max(limits.min_turn_radius_m, 1.0))
    return out


def _inside(path: NDArray, box: Box | None) -> bool:
    return box is None or bool(np.all(path >= box.lo - 1e-9) and np.all(path <= box.hi + 1e-9))


def _floor(box: Box | None) -> float:
    return float(box.lo[2]) if box is not None else -math.inf
