"""Physical flight limits of method ``best``: climb, dive, turn radius, minimum altitude.

Definitions (the ones ``--json`` reports and the tests check):

* climb (dive) angle of a segment d = atan2(+dz, h) (atan2(-dz, h)), h = hypot(dx, dy);
* turn radius at an interior vertex = radius of the circle through it and its two
  neighbours, |a| |b| |a + b| / (2 |a x b|) for the segments a, b meeting there (3-D);
  collinear points going on = infinite, a collinear reversal (hairpin) = 0, and a vertex
  on its neighbour (zero-length segment) is skipped;
* altitude of every vertex but the start and goal (take-off and landing) above the floor.

A curve of curvature radius R sampled at any spacing gives circles of radius R through
consecutive samples, so the limits mean the same at any ``n_points``; the paper's per-vertex
pitch and turn angles (:func:`~threat_planner.core.optimise.smoothing.check_angles`, methods
``paper`` and ``improved``) do not: a 60 deg turn per vertex is a radius of ~2.5 m at 40
segments over a 100 m field and ~1.3 m at 80.

The optimiser sees the limits as smooth constraints g >= 0 (dimensionless, O(1)):
climb ``sin(c - angle)``, dive ``sin(v + angle)``, radius ``1 - R_min / R`` written
as ``1 - 2 R_min sqrt(|a x b|^2 / (|a|^2 |b|^2 |a + b|^2))`` (curvature, no division by a
vanishing cross product); the minimum altitude is a bound.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.optimise.limit_kernels import DEGENERATE, LimitTerm, measure

__all__ = ['FlightLimits', 'LimitCheck', 'check_limits', 'climb_angles', 'meets_limits',
           'constraint_jacobian', 'constraint_values', 'constraint_vjp', 'turn_radii']

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
        Smallest radius of the circle through three consecutive points [m]; 0 = off.
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
    """Radius of the circle through each interior vertex and its neighbours [m], (n-1,).

    Collinear points going on give inf, a collinear reversal 0; zero-length segments are
    skipped over (the circle is taken through the nearest distinct points).
    """
    p = np.asarray(points, float)
    d = np.diff(p, axis=0)
    ln = np.linalg.norm(d, axis=1)
    keep = np.concatenate([[True], ln > DEGENERATE * max(float(ln.max(initial=0.0)), 1.0)])
    p = p[keep]
    if len(p) < 3:
        return np.zeros(0)
    a, b = p[1:-1] - p[:-2], p[2:] - p[1:-1]
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, a + b))
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        r = la * lb * lc / (2.0 * cross)
    # Exactly collinear: straight on is no turn at all, straight back is a hairpin.
    flat = cross <= 1e-15 * la * lb
    dots = np.einsum('ik,ik->i', a, b)
    return np.where(flat, np.where(dots >= 0, np.inf, 0.0), r)


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
    axis = axis / np.linalg.norm(axis) if np.linalg.norm(axis) > 0 else np.array([1.0, 0.0])
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
        a, b = d[:-1], d[1:]
        c = a + b
        aa, bb, cc = (np.einsum('ik,ik->i', v, v) for v in (a, b, c))
        ab = np.einsum('ik,ik->i', a, b)
        den = np.maximum(aa * bb * cc, 1e-300)
        x = np.maximum(aa * bb - ab * ab, 0.0)
        rho = x / den
        # g = 1 - R_min / R = 1 - 2 R_min sqrt(rho): linear in the curvature, so a sharp
        # corner is a violation of a few units, not of hundreds. Its kink at collinear
        # points lies where g = 1, far from active, where the penalty is zero anyway.
        root = np.sqrt(rho + 1e-300)
        values.append(1.0 - 2.0 * limits.min_turn_radius_m * root)
        k4 = limits.min_turn_radius_m / root
        # rho = X / (A B C); X = |a|^2 |b|^2 - (a.b)^2, c = a + b.
        dx_a = 2.0 * (a * bb[:, None] - b * ab[:, None])
        dx_b = 2.0 * (b * aa[:, None] - a * ab[:, None])
        drho_a = dx_a / den[:, None] - rho[:, None] * (2 * a / np.maximum(aa, 1e-300)[:, None]
                                                       + 2 * c / np.maximum(cc, 1e-300)[:, None])
        drho_b = dx_b / den[:, None] - rho[:, None] * (2 * b / np.maximum(bb, 1e-300)[:, None]
                                                       + 2 * c / np.maximum(cc, 1e-300)[:, None])
        # a = x1 - x0, b = x2 - x1
        deriv = -k4[:, None, None] * np.stack([-drho_a, drho_a - drho_b, drho_b], axis=1)
        verts = np.stack([np.arange(n - 1), np.arange(1, n), np.arange(2, n + 1)], axis=1)
        blocks.append((np.arange(row, row + n - 1), verts, deriv))
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
    g, blocks = _blocks(points, limits)
    jac = np.zeros((len(g), len(points), 3))
    for rows, verts, deriv in blocks:
        for j in range(verts.shape[1]):
            jac[rows, verts[:, j]] += deriv[:, j]
    return jac


def warm_up() -> None:
    """Compile (or load from the cache) the kernels once, on a tiny problem."""
    term = LimitTerm(FlightLimits(30.0, 30.0, 10.0), 4)
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.9], [2.0, 1.0, 0.0], [3.0, 0.0, 0.5]])
    term.values(pts)
    term.penalty(pts, np.ones(term.rows), 10.0)
    measure(pts, 0.0)
