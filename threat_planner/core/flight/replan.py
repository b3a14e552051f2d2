"""Plan through threats in time: the planner's static picture, placed where it matters.

J_R of a moving threat is dominated by the stretch of path near its closest approach
(the integrand falls as 1/d^4). So a plan in time is a fixed point: place every threat
piece where it will be when the current guess passes closest to it (pieces the guess never
meets while they are active drop out), plan that static picture with the full planner
(its limits, zones and methods), time the new path at the cruise speed, and repeat from
it. Every candidate is scored by the exact timed J (:mod:`.timed_cost`) and the least is
kept, so the answer is never worse than the first static plan in the exact measure.
With threats that neither move nor change over the flight, the first plan is exact and
the only one, the plan :func:`threat_planner.core.planner.plan` makes.
"""

from __future__ import annotations

from dataclasses import dataclass
import time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.flight.entry import enter, Entry
from threat_planner.core.flight.timed_cost import closest_approach, timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.optimise.limits import FlightLimits
from threat_planner.core.planner import plan
from threat_planner.core.result import PlanResult
from threat_planner.core.world.airspace import Airspace, make_zone, Zone
from threat_planner.core.world.terrain import Terrain
from threat_planner.core.world.threats import Box, ThreatField

__all__ = ['TimedPlan', 'plan_in_time', 'static_picture']

#: Fixed-point rounds of a plan through moving threats (each one a full plan).
ROUNDS = 3
#: The rounds stop once no threat is placed more than this fraction of the box diagonal
#: from where the previous round placed it.
SETTLED = 0.002


@dataclass
class TimedPlan:
    """A plan in time.

    Attributes
    ----------
    points : NDArray
        Path (M, 3) [m], from the start to the goal.
    times : NDArray
        Planned time at each point (M,) [s], ``t0`` at the start, at the cruise speed.
    cost : Cost
        The exact timed J of it (:mod:`.timed_cost`).
    result : PlanResult
        The planner's result for the static picture the path was planned in.
    rounds : int
        Static plans made.
    latency_ms : float
        Wall time of the whole plan [ms].
    entry : Entry, optional
        How the path was brought onto the start heading (None without one).

    """

    points: NDArray
    times: NDArray
    cost: Cost
    result: PlanResult
    rounds: int
    latency_ms: float
    entry: Entry | None = None


def _times(points: NDArray, speed: float, t0: float) -> NDArray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return t0 + np.concatenate([[0.0], np.cumsum(seg)]) / speed


def static_picture(known: ThreatTimeline, guess: NDArray, guess_times: NDArray,
                   start: NDArray) -> tuple[ThreatField, list[Zone], NDArray]:
    """Each threat piece where the guess passes closest to it, with its lethal sphere.

    A lethal sphere that holds the start is shrunk to just below the start's distance
    (the plan leaves it; it could not start inside it). Returns the field, the lethal
    zones and the placed positions (P', 3) [m].
    """
    ids, f, origin, vel, on, _, lethal = known.pieces()
    dist, when = closest_approach(guess, guess_times, known)
    keep = np.flatnonzero(np.isfinite(dist))
    pos = origin[keep] + vel[keep] * (when[keep] - on[keep])[:, None]
    zones = []
    for j, k in enumerate(keep):
        r = lethal[k]
        if not np.isfinite(r):
            continue
        d0 = float(np.linalg.norm(start - pos[j]))
        if d0 <= r:
            r = 0.99 * d0
        if r > 1e-6:
            zones.append(make_zone('sphere', f'threats[{int(ids[k])}].lethal_radius',
                                   center=pos[j], radius=r))
    return ThreatField.from_arrays(pos.reshape(-1, 3), f[keep]), zones, pos


def _plan_static(threats: ThreatField, s: NDArray, g: NDArray, box: Box,
                 config: PlannerConfig, zones: tuple[Zone, ...], lethal: list[Zone],
                 terrain: Terrain | None, warm_start: PlanResult | None) -> PlanResult:
    """Plan the static picture; lethal spheres only where the plan without them enters one.

    The threat cost already keeps most paths far from a threat (a lethal sphere is
    usually well inside where 1/d^4 bites), and planning around zones is the airspace
    method, two orders of magnitude slower than a plan without (a 20-threat field: seconds
    against tens of milliseconds), too slow for a replan in flight.
    """
    air = Airspace(tuple(zones), terrain)
    result = plan(threats, s, g, box, config, warm_start=None if air else warm_start,
                  airspace=air or None)
    hit = [z for z in lethal if float(z.segment_distance(result.path[:-1],
                                                         result.path[1:])[0].min()) < 0]
    if not hit:
        return result
    return plan(threats, s, g, box, config, airspace=Airspace(tuple(zones) + tuple(hit),
                                                              terrain))


def plan_in_time(known: ThreatTimeline, start: ArrayLike, goal: ArrayLike, box: Box,
                 config: PlannerConfig, speed: float, t0: float = 0.0, *,
                 zones: tuple[Zone, ...] = (), terrain: Terrain | None = None,
                 guess: NDArray | None = None, rounds: int = ROUNDS,
                 warm_start: PlanResult | None = None,
                 heading: NDArray | None = None) -> TimedPlan:
    """Plan from `start` at time `t0` to `goal` through the threats in time.

    Parameters
    ----------
    known : ThreatTimeline
        The threats as known now, each extrapolated at its velocity.
    start, goal : array_like
        (3,) [m], inside the box.
    box : Box
        Flight box.
    config : PlannerConfig
        Planner settings.
    speed : float
        Cruise speed [m/s].
    t0 : float
        Time at the start [s].
    zones : tuple of Zone
        Static no-fly zones (lethal spheres of threats come from `known`).
    terrain : Terrain, optional
        Terrain to clear.
    guess : NDArray, optional
        A path to place the threats by first (default: the straight line).
    rounds : int
        Most static plans (module docstring).
    warm_start : PlanResult, optional
        The previous static result, for a warm replan where the planner allows one.
    heading : NDArray, optional
        Unit direction the vehicle flies at the start: the plan leaves along it
        (:func:`.entry.enter`); None for a start at rest.

    Returns
    -------
    TimedPlan

    """
    clock = time.perf_counter()
    s, g = np.asarray(start, float), np.asarray(goal, float)
    path = np.array([s, g]) if guess is None else np.asarray(guess, float)
    moving = known.moving()
    best: TimedPlan | None = None
    placed = None
    diag = float(np.linalg.norm(box.hi - box.lo))
    done = 0
    for _ in range(max(1, rounds) if moving else 1):
        field_, lethal, pos = static_picture(known, path, _times(path, speed, t0), s)
        if placed is not None and len(pos) == len(placed) and (
                len(pos) == 0 or np.max(np.linalg.norm(pos - placed, axis=1)) <= SETTLED * diag):
            break
        placed = pos
        result = _plan_static(field_, s, g, box, config, zones, lethal, terrain, warm_start)
        done += 1
        pts = result.path
        times = _times(pts, speed, t0)
        cost = timed_path_cost(pts, times, known, config.w)
        if best is None or cost.J < best.cost.J:
            best = TimedPlan(pts, times, cost, result, 0, 0.0)
            best_field, best_lethal = field_, lethal
        path = pts
        warm_start = result
    if heading is not None:
        # Onto the heading once, for the round kept: a turn-in changes only the first
        # vertices (a replan from where the pursuit turned may follow).
        def again(point: NDArray) -> NDArray:
            return _plan_static(best_field, point, g, box, config, zones, best_lethal,
                                terrain, None).path

        entered = enter(best.points, heading, box if config.confine_to_box else None,
                        FlightLimits.of(config), replan=again,
                        zones=tuple(zones) + tuple(best_lethal))
        best.points, best.entry = entered.points, entered
        best.times = _times(best.points, speed, t0)
        best.cost = timed_path_cost(best.points, best.times, known, config.w)
    best.rounds = done
    best.latency_ms = 1e3 * (time.perf_counter() - clock)
    return best
