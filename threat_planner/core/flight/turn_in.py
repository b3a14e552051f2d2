"""A turn-in that is flyable by construction: a pursuit of the plan within the limits.

From the start ``s`` along the heading ``h``, a point moves in steps of ``STEP`` turn
radii, turning toward a point ``LOOK`` turn radii ahead on the plan at most as tightly as
the radius allows (with a margin, so that the polyline of its positions passes the fillet
rule of :mod:`threat_planner.core.optimise.limits`) and with its flight-path angle held
within the climb and dive limits; near the floor (plus ``min_altitude_m``) it pulls up in
time, and near the ceiling of the box it levels off. Once it flies along the plan (within
``ON_PATH`` turn radii of it, and its direction within ``ALIGNED_DEG``), the plan's own
vertices take over at the first joint whose path keeps every limit and the box; failing
all of them the pursuit goes on, through the goal where the last step into it keeps the
limits. :func:`pursue_plan` returns the joined path (:mod:`.entry` uses it).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.world.zones import Zone

__all__ = ['outside', 'Pursuit', 'pursue_plan']

#: Step of the pursuit, in turn radii: a chord of 0.25 R turns the fillet radius of the
#: pursued arc down by 0.5 %, within MARGIN.
STEP = 0.25
#: The pursuit turns at MARGIN times the turn radius.
MARGIN = 1.02
#: Look-ahead of the pursuit, in turn radii.
LOOK = 1.0
#: Look-aheads of its height tried in turn, in turn radii.
LOOK_Z = (1.0, 3.0, 6.0)
#: Joints are tried once the pursuit is within this many turn radii of the plan...
ON_PATH = 0.5
#: ...flying within this angle of its direction [deg] (the check of the joined path
#: decides; a pursuit that lags a climb at the climb limit never closes in fully).
ALIGNED_DEG = 30.0
#: Joints tried after the pursuit is on the plan, one plan vertex apart.
JOINTS = 6
#: A pursuit that has turned onto the plan and flown this many turn circles' length
#: since without a joint gives up (a failing one flew on to its step budget: 27 ms).
GIVE_UP_TURNS = 2.0


def _unit(v: NDArray) -> NDArray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def _turn_toward(v: NDArray, d: NDArray, most: float) -> NDArray:
    """Rotate unit `v` toward unit `d` by at most `most` [rad], in their plane."""
    c = float(np.clip(v @ d, -1.0, 1.0))
    angle = math.acos(c)
    if angle <= most:
        return d
    side = d - c * v
    if float(np.linalg.norm(side)) < 1e-12:    # straight back: turn level, either way
        side = np.cross([0.0, 0.0, 1.0], v)
        if float(np.linalg.norm(side)) < 1e-12:
            side = np.array([1.0, 0.0, 0.0])
    side = _unit(side)
    return math.cos(most) * v + math.sin(most) * side


def _yaw(v: NDArray, angle: float) -> NDArray:
    """Rotate `v` about the vertical by `angle` [rad] (positive: to the left)."""
    c, s_ = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s_ * v[1], s_ * v[0] + c * v[1], v[2]])


def _hold_pitch(v: NDArray, climb_deg: float, dive_deg: float) -> NDArray:
    h = math.hypot(v[0], v[1])
    pitch = math.degrees(math.atan2(v[2], h))
    lo, hi = -min(dive_deg, 89.0), min(climb_deg, 89.0)
    if lo <= pitch <= hi:
        return v
    p = math.radians(min(max(pitch, lo), hi))
    horiz = v[:2] / h if h > 1e-12 else np.array([1.0, 0.0])
    return np.array([math.cos(p) * horiz[0], math.cos(p) * horiz[1], math.sin(p)])


@dataclass(frozen=True)
class Pursuit:
    """A pursuit's path and where it had turned onto the plan.

    Attributes
    ----------
    path : NDArray
        The path (M, 3) [m], its first segment along the heading.
    feasible : bool
        Whether it meets the limits.
    turned : NDArray or None
        The pursuit up to where it first flew along the plan (K, 3) [m] (None: never),
        from which a new plan may go on where the plan itself cannot be joined.
    turned_heading : NDArray or None
        Its direction there.

    """

    path: NDArray
    feasible: bool
    turned: NDArray | None = None
    turned_heading: NDArray | None = None


def pursue_plan(points: NDArray, heading: NDArray, limits: FlightLimits, floor_z: float,
                box: tuple[NDArray, NDArray] | None = None, zones: Sequence[Zone] = ()
                ) -> Pursuit:
    """Return the plan `points` entered along `heading` by a pursuit (module docstring).

    A pursuit that cannot close in on a plan climbing or diving at the limit (it lags
    below or above it for good) is flown again aiming its height further ahead
    (``LOOK_Z``), and the first one that joins within the limits is kept.

    Parameters
    ----------
    points : NDArray
        The plan (M, 3) [m]; ``points[0]`` is the start.
    heading : NDArray
        Unit direction at the start.
    limits : FlightLimits
        The turn radius, climb and dive the pursuit keeps.
    floor_z : float
        z of the box floor [m], for the altitude limit of the check.
    box : tuple of NDArray, optional
        Corners (lo, hi) [m] the path must stay within; near a wall the pursuit aims
        inside it.
    zones : sequence of Zone
        Zones the path must keep out of (a lethal sphere): a pursuit or joint that
        enters one does not count; another way round may not.

    Returns
    -------
    Pursuit
        The first pursuit's turn when none joins.

    """
    first = None
    # The pursuit's own way round first; then turning left, then right, at the full rate
    # until the plan is ahead (a U-turn at a wall must turn away from it).
    for side in (0, 1, -1):
        for look_z in LOOK_Z:
            got = _pursue(points, heading, limits, floor_z, look_z, box, side, zones)
            if got.feasible:
                return got
            first = first or got
    return first


def _pursue(points: NDArray, heading: NDArray, limits: FlightLimits, floor_z: float,
            look_z: float, box: tuple[NDArray, NDArray] | None, side: int = 0,
            zones: Sequence[Zone] = ()) -> Pursuit:
    """Fly one pursuit, aiming in height `look_z` turn radii ahead.

    With `side` +1 (-1) it first turns left (right) level at the full rate for as long
    as the plan's aim point is behind it.
    """
    pts = np.asarray(points, float)
    radius = max(limits.min_turn_radius_m, 1e-3 * float(np.linalg.norm(pts[-1] - pts[0])))
    step = STEP * radius
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    length = float(arc[-1])
    dense_s = np.linspace(0.0, length, max(int(length / (0.1 * step)) + 2, 3))
    dense = np.stack([np.interp(dense_s, arc, pts[:, c]) for c in range(3)], axis=1)
    last_dir = _unit(pts[-1] - pts[-2])
    climb = limits.max_climb_deg if limits.climb_on else 90.0
    dive = limits.max_dive_deg if limits.dive_on else 90.0
    most = step / (MARGIN * radius)
    low = floor_z + limits.min_altitude_m
    p, v = pts[0].copy(), _unit(np.asarray(heading, float))
    trail, i = [p.copy()], 0
    window = int(4 * step / max(dense_s[1], 1e-12)) + 2
    cos_aligned = math.cos(math.radians(ALIGNED_DEG))
    turned = turned_heading = None
    budget = int(4 * (length + 2 * math.pi * radius) / step) + 10
    after_turn = int(GIVE_UP_TURNS * 2 * math.pi * radius / step)
    for n in range(budget):
        if turned is not None and n - len(turned) > after_turn:
            break      # on the plan's line, yet no joint holds: another way round may
        near = dense[i:i + window]
        i += int(np.argmin(np.linalg.norm(near - p, axis=1)))
        s_here = dense_s[i]
        aim = _along(pts, arc, last_dir, s_here + LOOK * radius)
        aim[2] = _along(pts, arc, last_dir, s_here + look_z * radius)[2]
        # Pull up in time: levelling off from a dive at angle a takes R (1 - cos a).
        pitch_now = math.asin(float(np.clip(v[2], -1.0, 1.0)))
        pull_up = (v[2] < 0 and p[2] - low
                   <= MARGIN * radius * (1.0 - math.cos(pitch_now)) + 2 * step)
        # ...and level off below the ceiling of the box likewise.
        push_down = (box is not None and v[2] > 0 and box[1][2] - p[2]
                     <= MARGIN * radius * (1.0 - math.cos(pitch_now)) + 2 * step)
        if box is not None:
            # Past the goal the aim runs on along the last segment: keep it in the box.
            # (Held a turn radius inside, it kept the pursuit 10 m off a plan along a
            # wall, never joining it.)
            aim = np.clip(aim, box[0], box[1])
        tangent = _unit(dense[min(i + 1, len(dense) - 1)] - dense[max(i - 1, 0)])
        if (len(trail) > 1 and float(np.linalg.norm(p - dense[i])) <= ON_PATH * radius
                and float(v @ tangent) >= cos_aligned and s_here < length - step):
            if turned is None:
                turned, turned_heading = np.array(trail), v.copy()
            joined = _join(trail, pts, arc, s_here, limits, floor_z, box, zones)
            if joined is not None:
                return Pursuit(joined, True, turned, turned_heading)
        if len(trail) > 1 and float(np.linalg.norm(pts[-1] - p)) <= 2 * step:
            path = np.vstack(trail + [pts[-1]])   # at the goal: ends here if it may
            if _fits(path, limits, floor_z, box, zones):
                return Pursuit(path, True, turned, turned_heading)
        if len(trail) > 1 and (pull_up or push_down):   # in its vertical plane, as tight
            flat = _unit(np.array([v[0], v[1], 0.0]))
            v = _turn_toward(v, flat if np.any(flat) else v, most)
        elif len(trail) > 1 and side and float(v @ _unit(aim - p)) < 0.0:
            v = _hold_pitch(_yaw(v, side * most), climb, dive)
        elif len(trail) > 1:     # the first step goes along the heading
            v = _hold_pitch(_turn_toward(v, _unit(aim - p), most), climb, dive)
        p = p + step * v
        trail.append(p.copy())
    path = np.vstack(trail + [pts[-1]])
    return Pursuit(path, _fits(path, limits, floor_z, box, zones), turned, turned_heading)


def _along(pts: NDArray, arc: NDArray, last_dir: NDArray, s: float) -> NDArray:
    """Return the point at arc length `s` of the plan, past its end along the last segment."""
    if s <= arc[-1]:
        return np.array([np.interp(s, arc, pts[:, c]) for c in range(3)])
    return pts[-1] + (s - arc[-1]) * last_dir


def _fits(path: NDArray, limits: FlightLimits, floor_z: float,
          box: tuple[NDArray, NDArray] | None, zones: Sequence[Zone] = ()) -> bool:
    """Return whether `path` meets the limits, stays in the box and out of the zones."""
    if box is not None and (np.any(path < box[0] - 1e-9) or np.any(path > box[1] + 1e-9)):
        return False
    if not check_limits(path, limits, floor_z).feasible:
        return False
    return outside(path, zones)


def outside(path: NDArray, zones: Sequence[Zone]) -> bool:
    """Return whether no segment of `path` enters any of `zones`."""
    return all(float(z.segment_distance(path[:-1], path[1:])[0].min()) >= 0.0
               for z in zones)


def _join(trail: list[NDArray], pts: NDArray, arc: NDArray, s_here: float,
          limits: FlightLimits, floor_z: float, box: tuple[NDArray, NDArray] | None,
          zones: Sequence[Zone] = ()) -> NDArray | None:
    """Return the trail joined to the plan's vertices, the first joint within the limits."""
    first = int(np.searchsorted(arc, s_here, side='right'))
    for j in range(first, min(first + JOINTS, len(pts))):
        # The joint segment at least as long as the one after the plan vertex, so the
        # vertex keeps the share it had in the plan.
        if j + 1 < len(pts) and arc[j] - s_here < arc[j + 1] - arc[j]:
            continue
        path = np.vstack(trail + [pts[j:]])
        if _fits(path, limits, floor_z, box, zones):
            return path
    return None
