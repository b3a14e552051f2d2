"""The vehicle at the node: odometry taken or refused, when it replans, where plans start.

The node's ``odom`` (nav_msgs/Odometry, :mod:`threat_planner.ros.conversions.odom`)
streams at tens of hertz; a replan per message would swamp the planner. The rule:

* **An odom replans** only when it is the first one flown from (no trajectory planned
  from the vehicle yet: since start-up, a ``start`` message or a frame change), or when
  the vehicle is more than :data:`ODOM_DRIFT_M` from the trajectory it flies (off track).
  Either way the plan starts at the vehicle, leaving along its heading. While a plan
  asked for with the vehicle known is on its way, and within :data:`ODOM_REPLAN_S` of
  the last replan an odom asked for (a replan that failed is not retried at the odom's
  rate), odometry only tracks. Any other odom only tracks: the node keeps the vehicle's
  state for the next plan.
* **Every other input** that replans (threats, zones, terrain, goal, parameters) plans
  from the vehicle. *In flight* when the trajectory being flown was planned from the
  vehicle and the vehicle was on it at its last odom (within ODOM_DRIFT_M): the shared
  replan step (:mod:`threat_planner.core.flight.commit`) keeps the next ``commit_s`` of
  it from where the vehicle is at t0 (its arc length at the last odom, moved on at
  ``speed_mps`` to t0: a vehicle whose odometry stopped is taken to fly its trajectory)
  and replans from its end to the goal now (a new goal too, as ``threat-planner fly``
  replans one: the committed stretch is flown first). Otherwise from the vehicle with its
  heading when its odometry is at most :data:`ODOM_STALE_S` old, else from ``start`` as
  before (a ``start`` message also ends planning from the vehicle until the next odom).
  Within ``commit_s`` of the goal on an unchanged goal, the trajectory stands: nothing is
  replanned.

A refused odom (another frame, NaN, outside the bounds) is counted (``odom_rejected`` in
every ``plan_info``, and ``inputs_rejected``); the node logs it and publishes an ERROR
``plan_info`` the first time for each kind of reason only, and keeps the last plan.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import re
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.flight.reference import ReferencePath
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.errors import InputError

__all__ = ['FlightTracker', 'Flown', 'MAX_CLOUD_SKEW_S', 'ODOM_DRIFT_M', 'ODOM_REPLAN_S',
           'ODOM_STALE_S', 'moving', 'timeline_of']

#: The vehicle is off the trajectory it flies beyond this distance from it [m].
ODOM_DRIFT_M = 5.0
#: Odometry older than this at a plan request is no start of a plan from the vehicle [s].
ODOM_STALE_S = 1.0
#: Odometry asks for a replan at most this often [s] (ArduPilot's avoidance: 1 Hz).
ODOM_REPLAN_S = 1.0
#: A moving threat cloud must be stamped within this of the node clock [s].
MAX_CLOUD_SKEW_S = 60.0
_NUMBER = re.compile(r'\b-?(?:nan|inf)\b|-?\d[\d.e+-]*')


def moving(velocities: Optional[NDArray]) -> bool:
    """Whether any threat velocity is non-zero."""
    return velocities is not None and bool(np.any(np.asarray(velocities) != 0))


def timeline_of(threats, velocities: Optional[NDArray], threats_t_ns: int,
                t0_ns: int) -> ThreatTimeline:
    """Return the threats in time on the plan's clock: t = 0 at `t0_ns`.

    Positions hold at `threats_t_ns`; one stamped after t0 is moved back along its
    velocity to t0, so every threat is known from the plan's start.
    """
    t_c = 1e-9 * (int(threats_t_ns) - int(t0_ns))
    if velocities is None or t_c <= 0:
        return ThreatTimeline(threats, velocities, t0=min(t_c, 0.0))
    shifted = threats.positions - np.asarray(velocities) * t_c
    return ThreatTimeline(type(threats).from_arrays(shifted, threats.intensities), velocities)


@dataclass(frozen=True)
class Flown:
    """The trajectory last published: the one the vehicle flies."""

    ref: ReferencePath
    goal: NDArray
    from_vehicle: bool
    seq: int


class FlightTracker:
    """What the node knows of the vehicle's flight, and the replan rule (module docstring)."""

    def __init__(self) -> None:
        self.flown: Optional[Flown] = None
        self.awaiting: Optional[int] = None
        self.odom_rejected = 0
        self._reasons: set[str] = set()
        self._last_trigger_ns: Optional[int] = None

    def reset(self) -> None:
        """Forget the trajectory flown (the frame changed)."""
        self.flown = None
        self.awaiting = self._last_trigger_ns = None

    def refused(self, reason: str) -> bool:
        """Count a refused odom; return whether its kind of reason is new (say it then)."""
        self.odom_rejected += 1
        key = _NUMBER.sub('#', reason)
        new = key not in self._reasons
        self._reasons.add(key)
        return new

    @staticmethod
    def took(state, kind: str, now_ns: int):
        """Return the state after an accepted input, with the node's clock where it counts.

        An odom gets its receipt time; an unstamped cloud holds at its receipt time.

        Raises
        ------
        InputError
            For a cloud of moving threats stamped more than MAX_CLOUD_SKEW_S from the node
            clock (the threats would be extrapolated that far).

        """
        if kind == 'odom':
            return replace(state, vehicle=replace(state.vehicle, received_ns=now_ns))
        if kind == 'threats':
            if state.threats_stamp_ns == 0:
                return replace(state, threats_stamp_ns=now_ns)
            skew = 1e-9 * (now_ns - state.threats_stamp_ns)
            if moving(state.velocities) and abs(skew) > MAX_CLOUD_SKEW_S:
                raise InputError(
                    f'PointCloud2 header.stamp: {state.threats_stamp_ns} ns is {skew:.3g} s '
                    f'from the node clock; a cloud of moving threats (vx vy vz) must be '
                    f'stamped within {MAX_CLOUD_SKEW_S:g} s of it')
        return state

    def trigger(self, state, now_ns: int) -> Optional[str]:
        """Return why an accepted odom replans, or None when it only tracks."""
        if state.threats is None or self.awaiting is not None or (
                self._last_trigger_ns is not None
                and now_ns - self._last_trigger_ns < ODOM_REPLAN_S * 1e9):
            return None
        f = self.flown
        reason = None
        if f is None or not f.from_vehicle:
            reason = 'first odom'
        else:
            drift = self._drift(f, state.vehicle.position)[1]
            if drift > ODOM_DRIFT_M:
                reason = f'off track by {drift:.3g} m'
        if reason is not None:
            self._last_trigger_ns = now_ns
        return reason

    @staticmethod
    def _drift(f: Flown, p: NDArray) -> tuple[float, float]:
        s = f.ref.project(p, 0.0, f.ref.length)
        return s, float(np.linalg.norm(f.ref.at(s) - p))

    def request_fields(self, state, now_ns: int) -> Optional[dict]:
        """Return the flight fields of a plan request; None when nothing is to be planned.

        With ``flown`` and ``s_now`` in flight; ``vehicle`` alone to plan from the
        vehicle; empty to plan from ``start`` (module docstring).
        """
        v = state.vehicle
        if v is None:
            return {}
        f = self.flown
        if f is not None and f.from_vehicle:
            s, drift = self._drift(f, v.position)
            if drift <= ODOM_DRIFT_M:
                cfg = state.settings.config
                s_now = min(s + cfg.speed_mps * 1e-9 * max(now_ns - v.received_ns, 0),
                            f.ref.length)
                if (f.ref.length - s_now <= cfg.speed_mps * cfg.commit_s
                        and np.array_equal(f.goal, state.goal)):
                    return None
                return {'vehicle': v, 'flown': f.ref.points, 's_now': s_now}
        return {'vehicle': v} if now_ns - v.received_ns <= ODOM_STALE_S * 1e9 else {}

    def requested(self, request) -> None:
        """Note a plan asked for: with the vehicle known, odometry only tracks until it is done."""
        if request.vehicle is not None:
            self.awaiting = request.seq

    def answered(self, seq: int) -> None:
        """Note that the plan for input `seq` ended (published, failed or timed out)."""
        if self.awaiting is not None and seq >= self.awaiting:
            self.awaiting = None

    def planned(self, request, points: NDArray) -> None:
        """Note the trajectory just published for `request`: the vehicle flies it now."""
        self.flown = Flown(ReferencePath(points), np.asarray(request.goal, float),
                           request.vehicle is not None, request.seq)
