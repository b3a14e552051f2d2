"""Thin a path to an autopilot's mission size, keeping its flight limits and clearances.

Douglas-Peucker with the constraints deciding: starting from start and goal, every span
whose chord breaks a limit or a clearance is split at its point farthest from the chord
(a turn radius too tight at a kept point splits both spans beside it), until none does;
then, while there is room, the point farthest from its chord over the whole path is added
where the path stays within them (a point that would break one is passed over). The
thinned path keeps only points of the plan, so its start, goal and altitudes are the
plan's.

"Within them" means no worse than the plan: every limit the plan meets (climb, dive, turn
radius, altitude; :mod:`threat_planner.core.optimise.limits`) the thinned path meets, one
the plan breaks it breaks by no more, and every segment stays outside every zone and
above the terrain floor where the plan's do. The J reported is the exact J of the thinned
path, as the planner scores a path (masked by the terrain when it masks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from threat_planner.core._vector import rows_dot
from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.cost.kernels import path_cost
from threat_planner.core.cost.masking import masked_cost
from threat_planner.core.optimise.limits import (check_limits, climb_angles, FlightLimits,
                                                 meets_limits, turn_radii)
from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.threats import Box, ThreatField
from threat_planner.errors import InputError, PlanningError

__all__ = ['Thinned', 'thin_path']

_SLACK = 1e-9


@dataclass(frozen=True)
class Thinned:
    """A thinned path.

    Attributes:
        points: The kept points (m, 3) [m].
        kept: Their indices in the plan's path (m,).
        cost: Exact J of the kept points.
    """

    points: NDArray
    kept: NDArray
    cost: Cost


def _deviation(path: NDArray, a: int, b: int) -> tuple[int, float]:
    """Return the point strictly between a and b farthest from the chord a->b, and its distance."""
    if b - a < 2:
        return -1, -1.0
    p, q = path[a], path[b]
    d = q - p
    inner = path[a + 1:b]
    # Not @: BLAS sums in a CPU's own order, and the kept points would follow it.
    t = np.clip(rows_dot(inner - p, d) / max(float(rows_dot(d, d)), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(inner - p - t[:, None] * d, axis=1)
    k = int(np.argmax(dist))
    return a + 1 + k, float(dist[k])


def _no_worse(path: NDArray, limits: FlightLimits, floor: float) -> FlightLimits:
    """Return the limits the thinned path must meet: the plan's own where it breaks one."""
    c = check_limits(path, limits, floor)
    return FlightLimits(max(limits.max_climb_deg, c.climb_deg) if limits.climb_on else 90.0,
                        max(limits.max_dive_deg, c.dive_deg) if limits.dive_on else 90.0,
                        min(limits.min_turn_radius_m, c.min_turn_radius_m),
                        min(limits.min_altitude_m, c.min_altitude_m))


class _Rules:
    """Which spans of a candidate break the limits or the airspace."""

    def __init__(self, path: NDArray, limits: FlightLimits, floor: float,
                 airspace: Optional[Airspace]) -> None:
        self.path, self.floor = path, floor
        self.limits = _no_worse(path, limits, floor)
        self.airspace = airspace or None
        # A span whose plan segments already break the airspace may keep doing so.
        self.plan_ok = (np.ones(len(path) - 1, bool) if self.airspace is None
                        else self.airspace.segment_ok(path[:-1], path[1:]))

    def bad_spans(self, keep: list[int]) -> set[int]:
        """Return the indices (into keep) of the spans to split."""
        pts = self.path[keep]
        lim, bad = self.limits, set()
        if self.airspace is not None:
            ok = self.airspace.segment_ok(pts[:-1], pts[1:])
            for s in np.flatnonzero(~ok):
                if self.plan_ok[keep[s]:keep[s + 1]].all():
                    bad.add(int(s))
        climb = climb_angles(pts)
        bad.update(int(s) for s in np.flatnonzero(
            (climb > lim.max_climb_deg + _SLACK) | (-climb > lim.max_dive_deg + _SLACK)))
        if lim.radius_on and len(pts) > 2:
            for v in np.flatnonzero(turn_radii(pts) < lim.min_turn_radius_m * (1 - 1e-6)):
                bad.update((int(v), int(v) + 1))
        return bad

    def ok(self, keep: list[int]) -> bool:
        """Whether a candidate meets every rule."""
        return (not self.bad_spans(keep)
                and meets_limits(self.path[keep], self.limits, self.floor))


def thin_path(path: NDArray, max_points: int, threats: ThreatField, box: Box, config,
              airspace: Optional[Airspace] = None) -> Thinned:
    """Thin a planned path to at most `max_points` points (see the module docstring).

    Args:
        path: The plan's path (n, 3) [m].
        max_points: Most points of the thinned path (>= 2).
        threats: The plan's threats (for J).
        box: The flight box (its floor for the altitude limit).
        config: The PlannerConfig planned with (w and the flight limits).
        airspace: No-fly zones and terrain, or None.

    Returns:
        The Thinned path (the plan itself when it is short enough).

    Raises:
        InputError: `max_points` below 2.
        PlanningError: the limits and clearances need more than `max_points` points,
            naming how many.
    """
    if int(max_points) != max_points or max_points < 2:
        raise InputError(f'max_waypoints: must be an integer >= 2 (start and goal), '
                         f'got {max_points!r}')
    path = np.asarray(path, float)
    n = len(path)
    rules = _Rules(path, FlightLimits.of(config), float(box.lo[2]), airspace)
    keep = [0, n - 1] if n > max_points else list(range(n))
    while n > max_points:
        bad = rules.bad_spans(keep)
        if not bad and rules.ok(keep):
            break
        if not bad:   # a limit only the whole check sees: split the longest-deviating span
            bad = set(range(len(keep) - 1))
        split = [_deviation(path, keep[s], keep[s + 1])[0] for s in sorted(bad)]
        split = [k for k in split if k >= 0]
        if not split:
            break
        keep = sorted(set(keep) | set(split))
    if len(keep) > max_points:
        raise PlanningError(f'max_waypoints: the flight limits and clearances need '
                            f'{len(keep)} of the path\'s {n} points, more than {max_points}')
    tried: set[int] = set()
    while len(keep) < min(max_points, n):
        spans = [_deviation(path, keep[s], keep[s + 1]) for s in range(len(keep) - 1)]
        best = max((sp for sp in spans if sp[0] >= 0 and sp[0] not in tried),
                   key=lambda sp: sp[1], default=None)
        if best is None:
            break
        tried.add(best[0])
        candidate = sorted(keep + [best[0]])
        if rules.ok(candidate):
            keep = candidate
    pts = path[keep]
    if airspace is not None and airspace.masking:
        cost = masked_cost(pts, threats, config.w, airspace)
    else:
        cost = path_cost(pts, threats.positions, threats.intensities, config.w)
    return Thinned(pts, np.array(keep), cost)
