"""Fly a scenario: plan, follow, and replan as threats pop up, move and leave.

The loop (``threat-planner fly``): plan at t = 0 from the start, then step the simulated
vehicle (:mod:`.vehicle`) every ``dt`` along the plan. When an event (:mod:`.events`) is
due, the planner learns it then (threats keep their announced velocity; it knows nothing
of later events), keeps the next ``commit_s`` of the path it flies unchanged, and replans
from the end of that stretch at the time the vehicle will be there
(:mod:`threat_planner.core.flight.commit`, the replan step the node takes).
A replan that fails (a start inside a new zone, no route) keeps the last good plan and
says so. The flown path is scored with the exact timed J against the true threats; so is
the plan made with hindsight (every event known at t = 0, to the final goal).

An optional *observer* watches the flight without changing it (``fly --record`` writes
it to a bag: :mod:`threat_planner.ros.recording.flight_record`). It has four methods,
each given copies:

* ``on_start(position, heading)``: the vehicle at t = 0, after the first plan;
* ``on_replan(record, points, times)``: each entry of ``replans`` as it is made, the
  first plan's included, with the trajectory published then (points (M, 3) [m], times
  (M,) [s] from take-off); None and None when it published none (failed, arriving);
* ``on_event(t, event)``: an event as it is applied, at the step time `t` [s];
* ``on_step(t, position, heading)``: the vehicle after each step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.flight.commit import commit, replan_in_flight
from threat_planner.core.flight.reference import ReferencePath
from threat_planner.core.flight.replan import plan_in_time, TimedPlan
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.world.airspace import Zone
from threat_planner.errors import InputError, PlanningError, ThreatPlannerError
from threat_planner.flight.events import apply_event, Event
from threat_planner.flight.follow import follow_step
from threat_planner.flight.vehicle import PointMass

__all__ = ['finite_json', 'FlightReport', 'fly', 'scenario_timeline']

#: Simulation step [s] (the flown path's spacing in time; the issue asks for <= 0.1 s).
DT = 0.05
#: A flight has reached its goal when it passes this close to it [m].
GOAL_TOLERANCE = 1.0


@dataclass
class FlightReport:
    """What a simulated flight did (``--json`` layout: :meth:`as_dict`)."""

    times: NDArray
    path: NDArray
    replans: list[dict]
    flown: Cost
    hindsight: Cost | None
    max_jump_m: float
    max_tracking_m: float
    reached_goal: bool
    limits: dict
    lethal: list[dict] = field(default_factory=list)
    speed_mps: float = 0.0
    goal_miss_m: float = math.inf
    hindsight_path: NDArray | None = None

    def as_dict(self) -> dict:
        """JSON-ready dictionary."""
        def cost(c: Cost | None) -> dict | None:
            return None if c is None else {'J': c.J, 'J_L': c.J_L, 'J_R': c.J_R}
        return {
            'speed_mps': self.speed_mps,
            'flown': {'t': [round(float(t), 6) for t in self.times],
                      'path': self.path.tolist()},
            'replans': self.replans,
            'J_flown': self.flown.J, 'flown_cost': cost(self.flown),
            'J_hindsight': None if self.hindsight is None else self.hindsight.J,
            'hindsight_cost': cost(self.hindsight),
            'hindsight_path': (None if self.hindsight_path is None
                               else self.hindsight_path.tolist()),
            'max_jump_m': self.max_jump_m, 'max_tracking_m': self.max_tracking_m,
            'reached_goal': self.reached_goal,
            'goal_miss_m': self.goal_miss_m if math.isfinite(self.goal_miss_m) else None,
            # A straight flight's turn radius is inf: JSON has none, so null.
            'flown_limits': {k: (None if isinstance(v, float) and not math.isfinite(v)
                                 else v) for k, v in self.limits.items()},
            'lethal_entries': self.lethal,
        }


def finite_json(value: object) -> object:
    """Return `value` with NaN and infinities as None and numpy values as Python ones.

    For strict JSON (``allow_nan=False``): a report, the events, a flight bag's setup.
    """
    if isinstance(value, dict):
        return {str(k): finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [finite_json(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def scenario_timeline(scenario) -> ThreatTimeline:
    """Return the scenario's threats at t = 0 with their velocities and lethal radii."""
    lethal = scenario.airspace.lethal_radii(len(scenario.threats))
    return ThreatTimeline(scenario.threats, getattr(scenario, 'velocities', None), lethal)


def _static_zones(scenario) -> list[Zone]:
    return [z for z in scenario.airspace.zones if not z.label.startswith('threats[')]


class _Flight:
    """State of one flight: the plan followed, the vehicle, what the planner knows."""

    def __init__(self, scenario, config: PlannerConfig, speed: float, commit_s: float,
                 dt: float, heading: NDArray | None) -> None:
        self.sc, self.cfg, self.speed, self.commit_s, self.dt = (scenario, config, speed,
                                                                 commit_s, dt)
        self.known = scenario_timeline(scenario)
        self.zones = _static_zones(scenario)
        self.terrain = scenario.airspace.terrain
        self.goal = np.asarray(scenario.goal, float)
        self.replans: list[dict] = []
        self.max_jump = 0.0
        first = self._plan(np.asarray(scenario.start, float), heading)
        if first is None:
            raise PlanningError(f"first plan: {self.replans[-1]['error']}")
        self.last = first
        self.published = (first.points, first.times)   # the trajectory flown, timed
        self.ref = ReferencePath(first.points)
        self.s_now = 0.0
        h = self.ref.tangent(0.0) if heading is None else heading
        self.vehicle = PointMass(np.asarray(scenario.start, float), h, speed,
                                 config.min_turn_radius_m, config.max_climb_deg,
                                 config.max_dive_deg)

    def _plan(self, start: NDArray, heading: NDArray | None) -> TimedPlan | None:
        """Make the first plan, from the start at t = 0."""
        try:
            p = plan_in_time(self.known, start, self.goal, self.sc.box, self.cfg, self.speed,
                             0.0, zones=tuple(self.zones), terrain=self.terrain,
                             heading=heading)
        except ThreatPlannerError as exc:
            self._failed(0.0, 'start', exc)
            return None
        self._planned(0.0, 'start', p)
        return p

    def _failed(self, t: float, reason: str, exc: ThreatPlannerError) -> None:
        self.replans.append({'t': t, 'latency_ms': None, 'reason': reason, 'ok': False,
                             'error': str(exc)})

    def _planned(self, t: float, reason: str, p: TimedPlan) -> None:
        self.replans.append({'t': t, 'latency_ms': round(p.latency_ms, 3),
                             'reason': reason, 'ok': True, 'rounds': p.rounds,
                             'J_planned': p.cost.J, 'warm': bool(p.result.warm)})
        if p.entry is not None:
            self.replans[-1].update(entry_turn_deg=round(p.entry.turn_deg, 3),
                                    entry_feasible=p.entry.feasible,
                                    entry_clear=p.entry.clear)

    def replan(self, t: float, reason: str) -> bool:
        """Keep commit_s of the current path and replan from its end (module docstring).

        The step the node takes too: :func:`threat_planner.core.flight.commit.commit`,
        then :func:`~threat_planner.core.flight.commit.replan_in_flight`. A failed replan
        is reported at the event's time, like one that succeeds, its t0 (the commit
        point's time) as ``t0``. Returns whether a
        new trajectory is flown (``published``).
        """
        kept = commit(self.ref, self.s_now, t, self.goal, self.speed, self.commit_s)
        if kept.arriving:
            self.replans.append({'t': t, 'latency_ms': 0.0, 'reason': reason, 'ok': True,
                                 'note': 'arriving: nothing left to replan'})
            return False
        try:
            flight = replan_in_flight(self.known, kept, self.sc.box, self.cfg,
                                      zones=tuple(self.zones), terrain=self.terrain)
        except ThreatPlannerError as exc:
            self._failed(t, reason, exc)   # at the event, like a replan that succeeds
            self.replans[-1]['t0'] = kept.t_end
            return False
        new = flight.plan
        self._planned(t, reason, new)
        old = self.ref
        self.ref = ReferencePath(flight.points)
        self.last = new
        # The commanded path must not move under the vehicle: compare the committed
        # stretch before and after, and the joint.
        ds = np.linspace(0.0, kept.s_end - self.s_now, 21)
        jump = np.linalg.norm(self.ref.at(ds) - old.at(self.s_now + ds), axis=1).max()
        self.max_jump = max(self.max_jump, float(jump),
                            float(np.linalg.norm(new.points[0] - kept.end)))
        self.s_now = 0.0
        self.published = (flight.points, flight.times)
        return True

    def step(self) -> float:
        """Fly one step; return the distance from the path after it [m]."""
        self.s_now, off = follow_step(self.vehicle, self.ref, self.s_now, self.dt)
        return off


def _lethal_entries(path: NDArray, times: NDArray, truth: ThreatTimeline) -> list[dict]:
    ids, _, origin, vel, on, off, lethal = truth.pieces()
    out = []
    for k in np.flatnonzero(np.isfinite(lethal)):
        live = (times >= on[k]) & (times < off[k])
        q = origin[k] + vel[k] * (times - on[k])[:, None]
        inside = live & (np.linalg.norm(path - q, axis=1) < lethal[k])
        if inside.any():
            out.append({'index': int(ids[k]), 'appeared_t': float(on[k]),
                        'first_t': float(times[inside][0]), 'last_t': float(times[inside][-1])})
    return out


def _copies(published: tuple[NDArray, NDArray]) -> tuple[NDArray, NDArray]:
    return tuple(np.array(a, float) for a in published)


def fly(scenario, events: list[Event], config: PlannerConfig, speed: float, *,
        commit_s: float = 2.0, dt: float = DT, heading: NDArray | None = None,
        max_time_s: float | None = None, hindsight: bool = True,
        observer=None) -> FlightReport:
    """Fly `scenario` through `events` (module docstring).

    Parameters
    ----------
    scenario : Scenario
        Box, start, goal, threats (with velocities), zones.
    events : list of Event
        In time order (:func:`.events.parse_events`).
    config : PlannerConfig
        Planner settings; the vehicle keeps its turn, climb and dive limits.
    speed : float
        Cruise speed [m/s].
    commit_s : float
        Stretch of the current path kept unchanged by a replan [s].
    dt : float
        Simulation step [s].
    heading : NDArray, optional
        Initial unit velocity direction (default: along the first plan).
    max_time_s : float, optional
        Longest flight [s]; default three times the first plan's duration plus the last
        event's time plus 30 s.
    hindsight : bool
        Also plan with every event known at t = 0 (J_hindsight).
    observer : object, optional
        Told of the flight as it goes (module docstring); None: nobody is.

    Returns
    -------
    FlightReport

    Raises
    ------
    InputError
        An event that cannot apply (a threat index that does not exist).
    PlanningError
        No first plan.

    """
    if not (math.isfinite(speed) and speed > 0):
        raise InputError(f'speed: must be finite and > 0, got {speed!r}')
    if not (math.isfinite(commit_s) and commit_s >= 0):
        raise InputError(f'commit_s: must be finite and >= 0, got {commit_s!r}')
    truth = scenario_timeline(scenario)
    truth_zones = _static_zones(scenario)
    final_goal = np.asarray(scenario.goal, float)
    for e in events:    # every event valid against the truth before the flight starts
        g = apply_event(e, truth, truth_zones)
        final_goal = final_goal if g is None else g
        if g is not None and not scenario.box.contains(g):
            raise InputError(f'{e.label}: {g.tolist()} is outside bounds '
                             f'{scenario.box.lo.tolist()}..{scenario.box.hi.tolist()}')
    flight = _Flight(scenario, config, speed, commit_s, dt, heading)
    if observer is not None:
        observer.on_replan(dict(flight.replans[-1]), *_copies(flight.published))
        observer.on_start(flight.vehicle.position.copy(), flight.vehicle.heading.copy())
    if max_time_s is None:
        last_event = events[-1].t if events else 0.0
        max_time_s = 3 * flight.ref.length / speed + last_event + 30.0
    t, k = 0.0, 0
    times, path, tracking = [0.0], [flight.vehicle.position.copy()], 0.0
    reached, miss = False, float('inf')
    while t < max_time_s:
        reasons = []
        while k < len(events) and events[k].t <= t + 1e-9:
            g = apply_event(events[k], flight.known, flight.zones)
            if g is not None:
                flight.goal = g
            reasons.append(events[k].describe())
            if observer is not None:
                observer.on_event(t, events[k])
            k += 1
        if reasons:
            new = flight.replan(t, '; '.join(reasons))
            if observer is not None:
                observer.on_replan(dict(flight.replans[-1]),
                                   *(_copies(flight.published) if new else (None, None)))
        before = flight.vehicle.position.copy()
        tracking = max(tracking, flight.step())
        after = flight.vehicle.position
        # Arrival: the step passes within GOAL_TOLERANCE of the goal; the flight ends at
        # its closest point (reported as goal_miss_m), not snapped onto the goal.
        d = after - before
        u = float(np.clip((flight.goal - before) @ d / max(d @ d, 1e-300), 0.0, 1.0))
        closest = before + u * d
        miss = float(np.linalg.norm(closest - flight.goal))
        if miss <= GOAL_TOLERANCE:
            t += u * dt
            times.append(t)
            path.append(closest)
            reached = True
            if observer is not None:
                observer.on_step(t, closest.copy(), flight.vehicle.heading.copy())
            break
        t += dt
        times.append(t)
        path.append(after.copy())
        if observer is not None:
            observer.on_step(t, after.copy(), flight.vehicle.heading.copy())
    times, path = np.asarray(times), np.asarray(path)
    check = check_limits(path, FlightLimits.of(config), float(scenario.box.lo[2]))
    limits = {'feasible': check.feasible, 'climb_deg': check.climb_deg,
              'dive_deg': check.dive_deg, 'min_turn_radius_m': check.min_turn_radius_m,
              'violations': check.violations}
    best = None
    if hindsight:
        best = plan_in_time(truth, scenario.start, final_goal, scenario.box, config, speed,
                            0.0, zones=tuple(truth_zones), terrain=scenario.airspace.terrain,
                            heading=heading)
    return FlightReport(times, path, flight.replans, timed_path_cost(path, times, truth,
                                                                     config.w),
                        None if best is None else best.cost, flight.max_jump, tracking,
                        reached, limits, _lethal_entries(path, times, truth), speed,
                        miss if reached else float(np.linalg.norm(path[-1] - flight.goal)),
                        None if best is None else best.points)
