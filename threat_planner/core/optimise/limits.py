"""Physical flight limits of method ``best``: climb, dive, turn radius, minimum altitude.

Definitions (the ones ``--json`` reports and the tests check):

* climb (dive) angle of a segment d = atan2(+dz, h) (atan2(-dz, h)), h = hypot(dx, dy);
* turn radius at an interior vertex = radius of the largest arc tangent to both segments
  whose tangent points lie on the vertex's share of them: share / tan(theta / 2), theta
  the turn between the segments (3-D), the share half of each segment, all of the first
  and last (the start and goal do not turn); straight on = infinite, a hairpin = 0, and
  a vertex on its neighbour (zero-length segment) is skipped;
* altitude of every vertex but the start and goal (take-off and landing) above the floor.

A path whose every radius is at least R flies as its segments joined by arcs of radius R,
each arc on its own share of the segments, none overlapping the next. A circle of radius
R sampled at spacing s gives R cos(phi / 2), phi = 2 asin(s / 2 R): R as s shrinks, 3 %
less at s = R / 2. The radius of the circle through three points, the rule before, passes
a 154 deg turn at a 1 m segment beside a 9.5 m one (10.0 m), which no aircraft flies.
The paper's per-vertex angles (``check_angles`` in :mod:`.smoothing`, methods ``paper``
and ``improved``) mean different things at different ``n_points``: 60 deg per vertex is a
radius of ~2.5 m at 40 segments over a 100 m field and ~1.3 m at 80.

The optimiser sees the limits as smooth constraints g >= 0 (dimensionless, O(1)):
climb ``sin(c - angle)``, dive ``sin(v + angle)``, and for the radius two rows a vertex,
one for each segment's share: ``t cos(theta / 2) - sin(theta / 2)``, t = share / R_min,
which is >= 0 exactly where tan(theta / 2) <= t (a hairpin -1), computed as
``(t |u + v| - |u - v|) / 2`` from the segments' directions u, v; its slope along a
segment's length does not vanish as the segment shrinks. The minimum altitude is a bound.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core._vector import vector_length
from threat_planner.core.optimise.limit_kernels import _EPS, DEGENERATE, LimitTerm, measure

__all__ = ['FlightLimits', 'LimitCheck', 'check_limits', 'climb_angles', 'meets_limits',
           'constraint_jacobian', 'constraint_values', 'constraint_values_jacobian',
           'constraint_vjp', 'turn_radii']

#: Slack of the final check, so a path optimised onto a limit is not failed by rounding.
CHECK_SLACK = 1e-6


@dataclass(frozen=True)
class FlightLimits:
    """The limits in force; 90 / 90 / 0 / 0 switch every one off.

    Attributes
    ----------
    max_climb_deg : float
        Largest flight-path angle upwards [deg]; 90 = off.
    max_dive_deg : float
        Largest flight-path angle downwards [deg]; 90 = off.
    min_turn_radius_m : float
        Smallest fillet radius at any interior vertex (module docstring) [m]; 0 = off.
    min_altitude_m : float
        Lowest height of the interior vertices above the box floor [m]; 0 = off.

    """

    max_climb_deg: float = 90.0
    max_dive_deg: float = 90.0
    min_turn_radius_m: float = 0.0
    min_altitude_m: float = 0.0

    @classmethod
    def of(cls, config: object) -> 'FlightLimits':
        """Return the limits of a PlannerConfig."""
        return cls(config.max_climb_deg, config.max_dive_deg, config.min_turn_radius_m,
                   config.min_altitude_m)

    @property
    def climb_on(self) -> bool:
        """The climb limit constrains anything."""
        return self.max_climb_deg < 90.0

    @property
    def dive_on(self) -> bool:
        """The dive limit constrains anything."""
        return self.max_dive_deg < 90.0

    @property
    def radius_on(self) -> bool:
        """The turn radius limit constrains anything."""
        return self.min_turn_radius_m > 0.0

    @property
    def any_constraint(self) -> bool:
        """Some limit needs constraints (the altitude is a bound, not a constraint)."""
        return self.climb_on or self.dive_on or self.radius_on

    def tightened(self, angle_deg: float, radius_fraction: float) -> 'FlightLimits':
        """Stricter limits by a margin, for the optimiser to aim inside the real ones."""
        return FlightLimits(
            max(self.max_climb_deg - angle_deg, 0.0) if self.climb_on else 90.0,
            max(self.max_dive_deg - angle_deg, 0.0) if self.dive_on else 90.0,
            self.min_turn_radius_m * (1.0 + radius_fraction), self.min_altitude_m)

    def as_dict(self) -> dict[str, float]:
        """JSON form: ``{max_climb_deg, max_dive_deg, min_turn_radius_m, min_altitude_m}``."""
        return {'max_climb_deg': self.max_climb_deg, 'max_dive_deg': self.max_dive_deg,
                'min_turn_radius_m': self.min_turn_radius_m,
                'min_altitude_m': self.min_altitude_m}


@dataclass(frozen=True)
class LimitCheck:
    """A path's own values against the limits in force.

    Attributes
    ----------
    climb_deg : float
        Steepest climb of any segment [deg] (negative if every segment descends).
    dive_deg : float
        Steepest dive of any segment [deg] (negative if every segment climbs).
    min_turn_radius_m : float
        Smallest turn radius over the interior vertices [m]; inf for a straight path.
    min_altitude_m : float
        Lowest interior vertex above the box floor [m]; inf without interior vertices.
    violations : dict
        Excess over each broken limit in its unit (``climb_deg``, ``dive_deg`` [deg],
        ``turn_radius_m``, ``altitude_m`` [m]); empty when feasible.
    worst : str or None
        The violation largest relative to its limit, or None.

    """

    climb_deg: float
    dive_deg: float
    min_turn_radius_m: float
    min_altitude_m: float
    violations: dict
    worst: str | None

    @property
    def feasible(self) -> bool:
        """Every limit is met."""
        return not self.violations

    def as_dict(self) -> dict:
        """JSON form (infinities as None)."""
        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None
        return {'climb_deg': num(self.climb_deg), 'dive_deg': num(self.dive_deg),
                'min_turn_radius_m': num(self.min_turn_radius_m),
                'min_altitude_m': num(self.min_altitude_m),
                'violations': dict(self.violations), 'worst_violation': self.worst}


def climb_angles(points: NDArray) -> NDArray:
    """Flight-path angle of each segment, atan2(dz, horizontal length) [deg], (n,)."""
    d = np.diff(np.asarray(points, float), axis=0)
    return np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))


def turn_radii(points: NDArray) -> NDArray:
    """Fillet radius at each interior vertex [m], (n-1,): share / tan(theta / 2).

    The share is half of each segment beside the vertex, all of the first and last one
    (the module docstring). Straight on gives inf, straight back 0; zero-length segments
    are skipped over (the fillet is taken between the nearest distinct points).
    """
    p = np.asarray(points, float)
    d = np.diff(p, axis=0)
    ln = np.linalg.norm(d, axis=1)
    keep = np.concatenate([[True], ln > DEGENERATE * max(float(ln.max(initial=0.0)), 1.0)])
    p = p[keep]
    if len(p) < 3:
        return np.zeros(0)
    seg = np.diff(p, axis=0)
    length = np.linalg.norm(seg, axis=1)
    share = 0.5 * length
    share[[0, -1]] = length[[0, -1]]
    a, b = seg[:-1], seg[1:]
    la, lb = length[:-1], length[1:]
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    along = la * lb + np.einsum('ik,ik->i', a, b)
    with np.errstate(divide='ignore', invalid='ignore'):
        r = np.minimum(share[:-1], share[1:]) * along / cross
    # Exactly collinear: straight on is no turn at all, straight back is a hairpin.
    flat = cross <= 1e-15 * la * lb
    r = np.where(along <= 0.0, 0.0, r)
    return np.where(flat, np.where(along > la * lb, np.inf, 0.0), r)


def check_limits(points: NDArray, limits: FlightLimits, floor_z: float) -> LimitCheck:
    """Measure a path and compare it with the limits.

    Parameters
    ----------
    points : ndarray
        Path, (n+1, 3) [m].
    limits : FlightLimits
        The limits in force.
    floor_z : float
        z of the box floor [m].

    Returns
    -------
    LimitCheck

    """
    climb, dive, radius, alt = measure(points, floor_z)
    excess = _excess(climb, dive, radius, alt, limits)
    unit = {'climb_deg': max(limits.max_climb_deg, 1.0),
            'dive_deg': max(limits.max_dive_deg, 1.0),
            'turn_radius_m': limits.min_turn_radius_m,
            'altitude_m': max(limits.min_altitude_m, 1.0)}
    rel = {k: v / unit[k] for k, v in excess.items()}
    worst = max(rel, key=rel.get) if rel else None
    return LimitCheck(climb, dive, radius, alt, excess, worst)


def meets_limits(points: NDArray, limits: FlightLimits, floor_z: float) -> bool:
    """Whether a path meets the limits: ``check_limits(...).feasible``, for a hot loop."""
    return not _excess(*measure(points, floor_z), limits)


def _excess(climb: float, dive: float, radius: float, alt: float,
            limits: FlightLimits) -> dict[str, float]:
    """Breach of each limit a path's measures break (within CHECK_SLACK), by name."""
    excess = {}
    if climb > limits.max_climb_deg + CHECK_SLACK:
        excess['climb_deg'] = float(climb - limits.max_climb_deg)
    if dive > limits.max_dive_deg + CHECK_SLACK:
        excess['dive_deg'] = float(dive - limits.max_dive_deg)
    if radius < limits.min_turn_radius_m * (1.0 - CHECK_SLACK):
        excess['turn_radius_m'] = float(limits.min_turn_radius_m - radius)
    if alt < limits.min_altitude_m - CHECK_SLACK * max(limits.min_altitude_m, 1.0):
        excess['altitude_m'] = float(limits.min_altitude_m - alt)
    return excess


def _blocks(points: NDArray, limits: FlightLimits
            ) -> tuple[NDArray, list[tuple[NDArray, NDArray, NDArray]]]:
    """Constraint values and their derivatives, block by block.

    Returns ``(g, blocks)``; each block is ``(rows, vertices, derivative)`` with
    derivative[k, j] = dg[rows[k]] / dx[vertices[k, j]] (3-vectors), over all vertices.
    """
    p = np.asarray(points, float)
    d = np.diff(p, axis=0)
    n = len(d)
    ln = np.sqrt(np.einsum('ik,ik->i', d, d))
    safe = np.where(ln > 0, ln, 1.0)
    h = np.hypot(d[:, 0], d[:, 1])
    # dh/dd; a vertical segment has no horizontal direction, so take the start-goal one
    # (any horizontal unit vector is a subgradient; a zero one would be a false optimum).
    axis = p[-1, :2] - p[0, :2]
    span = vector_length(axis)
    axis = axis / span if span > 0 else np.array([1.0, 0.0])
    dh = np.zeros_like(d)
    flat = h > 0
    dh[flat, :2] = d[flat, :2] / h[flat, None]
    dh[~flat, :2] = axis
    seg_vertices = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    values, blocks, row = [], [], 0
    for on, limit, sign in ((limits.climb_on, limits.max_climb_deg, -1.0),
                            (limits.dive_on, limits.max_dive_deg, 1.0)):
        if not on:
            continue
        # g = sin(limit -+ angle) = (h sin(limit) -+ dz cos(limit)) / |d|: its slope
        # does not vanish at a vertical segment, as sin(limit) -+ dz / |d| would.
        sn, cs = math.sin(math.radians(limit)), math.cos(math.radians(limit))
        gv = (h * sn + sign * d[:, 2] * cs) / safe
        dg = sn * dh / safe[:, None] - (gv / safe)[:, None] * d / safe[:, None]
        dg[:, 2] += sign * cs / safe
        values.append(gv)
        blocks.append((np.arange(row, row + n), seg_vertices, np.stack([-dg, dg], axis=1)))
        row += n
    if limits.radius_on and n >= 2:
        # Two rows a vertex (module docstring): the share of the segment before it, then of
        # the one after it; a = x_i - x_(i-1), b = x_(i+1) - x_i, u and v their directions.
        a, b = d[:-1], d[1:]
        la, lb = np.maximum(ln[:-1], 1e-150)[:, None], np.maximum(ln[1:], 1e-150)[:, None]
        u, v = a / la, b / lb
        p_, m_ = u + v, u - v
        big_p = np.linalg.norm(p_, axis=1, keepdims=True)
        big_m = np.sqrt(np.einsum('ik,ik->i', m_, m_) + _EPS ** 2)[:, None]
        unit_p = np.divide(p_, big_p, out=np.zeros_like(p_), where=big_p > 1e-150)
        alpha = np.full(n, 0.5)
        alpha[[0, -1]] = 1.0
        verts = np.stack([np.arange(n - 1), np.arange(1, n), np.arange(2, n + 1)], axis=1)
        r_min = limits.min_turn_radius_m
        for side, (seg_len, seg_alpha) in enumerate(((la, alpha[:-1, None]),
                                                     (lb, alpha[1:, None]))):
            t = seg_alpha * seg_len / r_min
            values.append((0.5 * (t * big_p - (big_m - _EPS)))[:, 0])
            wa, wb = t * unit_p - m_ / big_m, t * unit_p + m_ / big_m
            da = 0.5 * (wa - u * np.einsum('ik,ik->i', u, wa)[:, None]) / la
            db = 0.5 * (wb - v * np.einsum('ik,ik->i', v, wb)[:, None]) / lb
            grow = 0.5 * big_p * seg_alpha / r_min
            if side == 0:
                da = da + grow * u
            else:
                db = db + grow * v
            blocks.append((np.arange(row, row + n - 1), verts,
                           np.stack([-da, da - db, db], axis=1)))
            row += n - 1
    g = np.concatenate(values) if values else np.zeros(0)
    return g, blocks


def constraint_values(points: NDArray, limits: FlightLimits) -> NDArray:
    """Constraint values g (>= 0 where the limits hold), climb, dive, then radius rows."""
    return _blocks(points, limits)[0]


def constraint_vjp(points: NDArray, limits: FlightLimits, weights: NDArray
                   ) -> tuple[NDArray, NDArray]:
    """Values g and the gradient of sum_k weights[k] g_k over every vertex, (n+1, 3).

    No dense Jacobian is formed, so it costs O(n) at any ``n_points``.
    """
    g, blocks = _blocks(points, limits)
    out = np.zeros((len(points), 3))
    for rows, verts, deriv in blocks:
        wr = weights[rows][:, None, None] * deriv
        for j in range(verts.shape[1]):
            np.add.at(out, verts[:, j], wr[:, j])
    return g, out


def constraint_jacobian(points: NDArray, limits: FlightLimits) -> NDArray:
    """Dense Jacobian dg/dx, (m, n+1, 3), for checks and small problems."""
    return constraint_values_jacobian(points, limits)[1]


def constraint_values_jacobian(points: NDArray, limits: FlightLimits
                               ) -> tuple[NDArray, NDArray]:
    """Values g and the dense Jacobian dg/dx (m, n+1, 3) from one pass over the path."""
    g, blocks = _blocks(points, limits)
    jac = np.zeros((len(g), len(points), 3))
    for rows, verts, deriv in blocks:
        for j in range(verts.shape[1]):
            jac[rows, verts[:, j]] += deriv[:, j]
    return g, jac


def warm_up() -> None:
    """Compile (or load from the cache) the kernels once, on a tiny problem."""
    term = LimitTerm(FlightLimits(30.0, 30.0, 10.0), 4)
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.9], [2.0, 1.0, 0.0], [3.0, 0.0, 0.5]])
    term.values(pts)
    term.penalty(pts, np.ones(term.rows), 10.0)
    term.values_jacobian(pts)
    measure(pts, 0.0)
