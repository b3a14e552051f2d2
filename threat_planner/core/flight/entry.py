"""Leave the start along the vehicle's heading: the first turn keeps the turn radius.

A plan from a vehicle in flight must start in the direction it flies: its first segment
along the heading ``h`` (no turn at the start, which the fillet rule of
:mod:`threat_planner.core.optimise.limits` does not check), the turns after it within
the limits. :func:`enter` makes a plan so. It pursues the plan from the start within the
limits (:mod:`.turn_in`: flyable by construction) until it flies along it, then joins the
plan's own vertices. Where the plan cannot be joined (it climbs at the limit above the
pursuit, say) and a ``replan`` is given, the picture is planned again from where the
pursuit had turned and that plan pursued. Failing that, SLSQP moves the plan's
first ENTRY_POINTS vertices instead (``start + l h`` first, l > 0 free) to the least J of
the static picture under the limits' smooth constraints. Where the plan already leaves
along the heading it is returned as it is.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.cost.kernels import cost_gradient as cost_and_gradient
from threat_planner.core.optimise.limits import (check_limits, constraint_jacobian,
                                                 constraint_values, FlightLimits)
from threat_planner.core.optimise.optimisation import aim
from threat_planner.core.flight.turn_in import pursue_plan
from threat_planner.core.world.threats import Box, ThreatField
from threat_planner.errors import InputError, ThreatPlannerError

__all__ = ['ENTRY_POINTS', 'Entry', 'enter', 'unit_heading']

#: Vertices after the start that move to bring the plan onto the heading.
ENTRY_POINTS = 10
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

    """

    points: NDArray
    changed: int
    feasible: bool
    turn_deg: float


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


def enter(points: ArrayLike, heading: ArrayLike, threats: ThreatField, box: Box | None,
          w: float, limits: FlightLimits,
          replan: Callable[[NDArray], NDArray] | None = None) -> Entry:
    """Return the plan `points` made to leave its start along `heading` (module docstring).

    Parameters
    ----------
    points : array_like
        A plan (M, 3) [m] from the start.
    heading : array_like
        Unit direction the vehicle flies at the start.
    threats : ThreatField
        The static picture the plan was made in (its J is minimised).
    box : Box, optional
        Bounds the moved vertices stay in.
    w : float
        Threat weight.
    limits : FlightLimits
        The limits every turn and segment must meet.
    replan : callable, optional
        ``replan(point)`` plans the same picture from `point` to the goal, (K, 3) [m];
        used where the pursuit cannot join the plan (module docstring).

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
    floor = _floor(box)
    corners = None if box is None else (box.lo, box.hi)
    # A pursuit of the plan within the limits is flyable by construction (.turn_in).
    # SLSQP from it never ended lower within the limits (18 headings on a 20-threat
    # field: 0 of 18, at 30-900 ms each against 1-3 ms for the pursuit), so it is kept.
    got = pursue_plan(pts, h, limits, floor, corners)
    if got.feasible:
        return Entry(got.path, len(got.path) - 1 - _tail_vertices(got.path, pts), True,
                     math.degrees(turn))
    guess = got.path
    if replan is not None and got.turned is not None:
        # The plan cannot be joined (it climbs at the limit above the pursuit, say): plan
        # again from where the pursuit had turned, and pursue that plan from there.
        try:
            again = replan(got.turned[-1])
        except ThreatPlannerError:
            again = None
        if again is not None:
            rest = pursue_plan(again, got.turned_heading, limits, floor, corners)
            # Without the joint vertex: the two steps either side of it are collinear,
            # and as one segment the turn after it keeps the share it had in `rest`.
            joined = np.vstack([got.turned[:-1], rest.path[1:]])
            if _inside(joined, box) and check_limits(joined, limits, floor).feasible:
                return Entry(joined, len(joined) - 1, True, math.degrees(turn))
    best, best_excess = guess, _excess(guess, limits, floor, box)
    changed = len(guess) - 1 - _tail_vertices(guess, pts)
    pitch = math.degrees(math.asin(float(np.clip(h[2], -1.0, 1.0))))
    hopeless = ((limits.climb_on and pitch > limits.max_climb_deg)
                or (limits.dive_on and -pitch > limits.max_dive_deg))
    # One SLSQP run, with one restart unless the heading itself breaks a limit: it is
    # the fallback, and each run takes 0.1-5 s (a wider second window took 10.6 s on a
    # bench flight under load and still broke the turn radius).
    tries = ((ENTRY_POINTS, 1.2, 0 if hopeless else 1),)
    for count, radius, restarts in tries:
        k = min(count, len(pts) - 3)
        x = None
        for _ in range(1 + restarts):
            out, x = _solve(pts, h, k, radius * limits.min_turn_radius_m, x, threats, box,
                            w, limits)
            check = check_limits(out, limits, floor)
            if check.feasible and _inside(out, box):
                return Entry(out, k, True, math.degrees(turn))
            excess = _excess(out, limits, floor, box)
            if excess < best_excess:
                best, best_excess, changed = out, excess, k
    return Entry(best, changed, False, math.degrees(turn))


def _tail_vertices(path: NDArray, plan: NDArray) -> int:
    """Return how many of `path`'s last vertices are the plan's own, unchanged."""
    n = 0
    while n < min(len(path), len(plan)) and np.array_equal(path[-1 - n], plan[-1 - n]):
        n += 1
    return n


def _solve(pts: NDArray, h: NDArray, k: int, radius: float, x0: NDArray | None,
           threats: ThreatField, box: Box | None, w: float, limits: FlightLimits
           ) -> tuple[NDArray, NDArray]:
    """Move vertices 1..k of `pts` (1 along `h`) to the least J under the limits.

    Returns the path and SLSQP's variables, which a second call takes as `x0`; without
    `x0` it starts from :func:`_turn_in` of `radius` [m].
    """
    from scipy.optimize import minimize
    # Window: start, P1 = start + l h, P2..Pk free, then up to three fixed vertices. The
    # window's last segment is all of the last vertex's share, in the path half of it
    # unless it ends at the goal: that row (of fixed vertices only) is dropped.
    s = pts[0]
    fixed_tail = pts[k + 1:k + 4]
    drop = k + 4 < len(pts)
    scale = float(np.linalg.norm(pts[-1] - pts[0])) or 1.0
    if x0 is None:
        guess = _turn_in(s, h, pts[k + 1], k, radius)
        x0 = np.concatenate([[max(float(np.linalg.norm(guess[0] - s)), 1e-3) / scale],
                             (guess[1:] / scale).ravel()])
    positions, f = threats.positions, threats.intensities

    def window(x: NDArray) -> NDArray:
        p1 = s + x[0] * scale * h
        return np.vstack([s[None], p1[None], x[1:].reshape(-1, 3) * scale, fixed_tail])

    def chain(d_window: NDArray) -> NDArray:
        """Return d/dx from d/d(window vertices)."""
        return np.concatenate([[d_window[1] @ h * scale],
                               (d_window[2:k + 1] * scale).ravel()])

    j0 = abs(cost_and_gradient(window(x0), positions, f, w)[0]) or 1.0

    def objective(x: NDArray) -> tuple[float, NDArray]:
        j, g = cost_and_gradient(window(x), positions, f, w)
        return j / j0, chain(g) / j0

    radius_on = limits.radius_on
    target = aim(limits)   # a hair inside, as the planner's optimisers aim

    def cons(x: NDArray) -> NDArray:
        g = constraint_values(window(x), target)
        return g[:-1] if radius_on and drop else g

    def cons_jac(x: NDArray) -> NDArray:
        jac = constraint_jacobian(window(x), target)
        if radius_on and drop:
            jac = jac[:-1]
        return np.stack([chain(row) for row in jac]) if len(jac) else np.zeros((0, len(x)))

    bounds = [(1e-6 / scale, None)]
    if box is not None:
        lo = box.lo.copy()
        lo[2] += limits.min_altitude_m
        bounds += [(a / scale, b / scale) for _ in range(k - 1)
                   for a, b in zip(lo, box.hi)]
    else:
        bounds += [(None, None)] * (3 * (k - 1))
    res = minimize(objective, x0, jac=True, method='SLSQP', bounds=bounds,
                   constraints=[{'type': 'ineq', 'fun': cons, 'jac': cons_jac}],
                   options={'maxiter': 200, 'ftol': 1e-9})
    out = pts.copy()
    out[:k + 1] = window(res.x)[:k + 1]
    return out, res.x


def _turn_in(s: NDArray, h: NDArray, target: NDArray, k: int, radius: float) -> NDArray:
    """Return `k` points on an arc of `radius` leaving `s` along `h`, then on to `target`.

    This is the start SLSQP refines: a smooth turn-in, near the limits.
    """
    to = target - s
    m = to - (to @ h) * h
    if np.linalg.norm(m) < 1e-12 or radius <= 0:
        path = np.array([s, target])
    else:
        m = m / np.linalg.norm(m)
        phi = np.linspace(0.0, math.pi, 721)
        arc = s + radius * (np.sin(phi)[:, None] * h + (1 - np.cos(phi))[:, None] * m)
        tangent = np.cos(phi)[:, None] * h + np.sin(phi)[:, None] * m
        rest = target - arc
        miss = np.linalg.norm(np.cross(tangent, rest), axis=1) / np.maximum(
            np.linalg.norm(rest, axis=1), 1e-300) + (np.einsum('ij,ij->i', tangent, rest) < 0)
        j = int(np.argmin(miss))
        path = np.vstack([arc[:j + 1], target[None]])
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    at = cum[-1] * np.arange(1, k + 1) / (k + 1)
    return np.stack([np.interp(at, cum, path[:, c]) for c in range(3)], axis=1)


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
