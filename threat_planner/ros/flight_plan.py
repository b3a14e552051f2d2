"""The node's plans in time: from the vehicle, in flight, and through moving threats.

A plan request is *timed* when the node knows the vehicle (an ``odom``) or a threat
moves (a cloud's ``vx vy vz``). It is then planned through the threats in time
(:func:`threat_planner.core.flight.replan.plan_in_time`), with the node's t0 (the
receipt of the input that asked for it, the paths' header stamp) as t = 0:

* **in flight** (the request carries the trajectory being flown and the vehicle's arc
  length on it): the shared replan step, :mod:`threat_planner.core.flight.commit`, keeps
  the next ``commit_s`` of it and replans from its end; the path published is the
  splice, its poses stamped with the splice's times;
* **from the vehicle** (an odom, no trajectory being flown): from the vehicle's position,
  leaving along its heading (:func:`threat_planner.core.flight.entry.enter`);
* **timed** (no odom, moving threats): from the ``start``, as the static plan does.

A threat cloud's positions hold at its stamp (its receipt time when unstamped): the
timeline's t0 is that time on the plan's clock, ``(stamp - t0) / 1e9`` [s]. ``J``,
``J_L`` and ``J_R`` in ``plan_info`` are the exact timed cost of the published path at
its times (:func:`threat_planner.core.flight.timed_cost.timed_path_cost`); the limits are
the replan's, from the joint on (the committed stretch was checked when it was planned).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.flight.commit import commit, replan_in_flight
from threat_planner.core.flight.replan import plan_in_time, TimedPlan
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.optimise.limits import check_limits
from threat_planner.core.optimise.smoothing import check_angles
from threat_planner.core.result import PlanResult
from threat_planner.core.trajectory import point_times
from threat_planner.errors import PlanningError
from threat_planner.ros.flight import moving, timeline_of

__all__ = ['FlightAnswer', 'is_timed', 'plan_flight']


@dataclass
class FlightAnswer:
    """A timed plan, ready for the node's messages.

    Attributes
    ----------
    points, times : NDArray
        The path published (M, 3) [m] and its times after t0 (M,) [s].
    initial_times : NDArray
        Times of the result's ``initial_path`` [s].
    result : PlanResult
        The static result, its path, cost, angles and limit check those of `points`.
    static : PlanResult
        The static result as planned (a warm start for the next plan).
    values : dict
        ``plan_info`` values of the flight (``plan``, ``start_heading``, entry, commit).

    """

    points: NDArray
    times: NDArray
    initial_times: NDArray
    result: PlanResult
    static: PlanResult
    values: dict


def is_timed(request) -> bool:
    """Whether a plan request plans in time (module docstring)."""
    return request.vehicle is not None or moving(request.velocities)


def plan_flight(request, warm_start: Optional[PlanResult] = None) -> FlightAnswer:
    """Plan a timed request (module docstring).

    Raises
    ------
    InputError, PlanningError
        As the planner does; PlanningError when the trajectory flown is within
        ``commit_s`` of the goal (the node does not ask for that plan).

    """
    s = request.settings
    cfg = s.config
    speed = cfg.speed_mps
    known = timeline_of(request.threats, request.velocities, request.threats_t_ns,
                        request.received_ns)
    air = request.airspace
    zones = tuple(air.zones) if air is not None else ()
    terrain = air.terrain if air is not None else None
    vel = request.velocities
    values: dict = {'moving_threats': 0 if vel is None else int(np.count_nonzero(
        np.any(np.asarray(vel) != 0, axis=1)))}
    if request.flown is not None:
        kept = commit(request.flown, request.s_now, 0.0, request.goal, speed, cfg.commit_s)
        if kept.arriving:
            raise PlanningError(f'the trajectory flown reaches the goal within commit_s='
                                f'{cfg.commit_s:g} s: nothing left to replan')
        flight = replan_in_flight(known, kept, s.box, cfg, zones=zones, terrain=terrain,
                                  warm_start=warm_start)
        timed, points, times, joint = flight.plan, flight.points, flight.times, flight.joint
        values.update({'plan': 'in_flight', 'committed_points': joint + 1,
                       'committed_m': kept.s_end - kept.s_now, 'commit_s': cfg.commit_s,
                       'replan_t_s': kept.t_end, 'replan_J': timed.cost.J})
        heading = kept.heading
    else:
        vehicle = request.vehicle
        heading = None if vehicle is None else vehicle.heading
        start = request.start if vehicle is None else vehicle.position
        timed = plan_in_time(known, start, request.goal, s.box, cfg, speed, 0.0, zones=zones,
                             terrain=terrain, heading=heading, warm_start=warm_start)
        points, times, joint = timed.points, timed.times, 0
        values['plan'] = 'timed' if vehicle is None else 'from_vehicle'
    values.update(_entry_values(timed, heading))
    values['rounds'] = timed.rounds
    if request.reason:
        values['plan_reason'] = request.reason
    if request.vehicle is not None:
        values['odom_age_s'] = 1e-9 * (request.received_ns - request.vehicle.received_ns)
        values['vehicle_speed_mps'] = request.vehicle.speed
    static = timed.result
    result = _as_published(static, points, times, joint, known, s.box, cfg)
    initial_times = times[joint] + point_times(static.initial_path, speed)
    return FlightAnswer(points, times, initial_times, result, static, values)


def _entry_values(timed: TimedPlan, heading: Optional[NDArray]) -> dict:
    if heading is None:
        return {}
    out = {'start_heading': '[' + ', '.join(f'{v:.9g}' for v in heading) + ']'}
    if timed.entry is not None:
        out.update({'entry_feasible': timed.entry.feasible,
                    'entry_turn_deg': timed.entry.turn_deg,
                    'entry_points_moved': timed.entry.changed})
    return out


def _as_published(static: PlanResult, points: NDArray, times: NDArray, joint: int,
                  known: ThreatTimeline, box, cfg) -> PlanResult:
    """Return the static result with the published path, its exact timed cost and checks."""
    cost = timed_path_cost(points, times, known, cfg.w)
    check = None if static.limit_check is None else check_limits(
        points[joint:], static.limits, float(box.lo[2]))
    return replace(static, path=points, cost=cost, limit_check=check,
                   angles=check_angles(points[joint:], cfg.max_pitch_deg, cfg.max_turn_deg))
