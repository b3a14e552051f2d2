"""Physical flight limits of a polyline: the definitions, a checker and smooth constraints.

The definitions (the ones the product will adopt):

* **climb / dive angle** of a segment = ``atan2(+-dz, horizontal length)``; the climb angle
  (dz > 0) must be <= ``max_climb_deg`` and the dive angle (dz < 0) <= ``max_dive_deg``.
* **turn radius** at an interior vertex = radius of the circle through it and its two
  neighbours in 3-D (collinear, including coincident, points: infinite); it must be
  >= ``min_turn_radius_m``.

:func:`flight_limits` and :func:`check_limits` evaluate these directly (side lengths and
triangle area, no optimiser code), so they are an independent check of what
:class:`LimitConstraints` enforces inside the optimiser. Note that a circumradius cannot
see a reversal: three almost collinear points with the middle one outside the other two
have a huge circle, so the turn-radius rule alone does not forbid a spike; the limited
yardstick keeps segments of nearly equal length, which rules such spikes out.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Tolerance of :func:`check_limits`: [deg] on angles, relative on the radius.
CHECK_TOL = 1e-6
# Complex-step size: derivatives exact to rounding, no subtraction error.
_CSTEP = 1e-30


@dataclass(frozen=True)
class Limits:
    """Flight limits of the limited yardstick.

    Attributes
    ----------
    max_climb_deg, max_dive_deg : float
        Largest climb and dive angle of a segment [deg].
    min_turn_radius_m : float
        Smallest turn radius at a vertex [m].
    """

    max_climb_deg: float
    max_dive_deg: float
    min_turn_radius_m: float

    def as_dict(self) -> dict[str, float]:
        """Return the three limits as a plain dict."""
        return {'max_climb_deg': self.max_climb_deg, 'max_dive_deg': self.max_dive_deg,
                'min_turn_radius_m': self.min_turn_radius_m}


def segment_angles(points: ArrayLike) -> NDArray:
    """Signed climb angle of every segment [deg] (positive up, negative down)."""
    d = np.diff(np.asarray(points, float), axis=0)
    return np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))


def turn_radii(points: ArrayLike) -> NDArray:
    """Radius of the circle through each interior vertex and its neighbours [m].

    R = a b c / (4 K) with a, b, c the triangle's sides and K its area; collinear or
    coincident points give ``inf``.
    """
    p = np.asarray(points, float)
    u = p[:-2] - p[1:-1]
    v = p[2:] - p[1:-1]
    a = np.linalg.norm(u, axis=1)
    b = np.linalg.norm(v, axis=1)
    c = np.linalg.norm(p[2:] - p[:-2], axis=1)
    twice_area = np.linalg.norm(np.cross(u, v), axis=1)
    # Area below rounding of the sides' product means the three points are collinear.
    flat = twice_area <= 1e-14 * np.maximum(a * b, 1e-300)
    with np.errstate(divide='ignore', invalid='ignore'):
        r = np.where(flat, np.inf, a * b * c / (2.0 * twice_area))
    return r


def flight_limits(points: ArrayLike) -> dict[str, float]:
    """Worst climb, dive and turn radius of a path.

    Returns
    -------
    dict
        ``max_climb_deg``, ``max_dive_deg`` (both >= 0, 0 for a level path),
        ``min_turn_radius_m`` (inf for a straight path or one segment) and
        ``spacing_ratio`` (longest over shortest segment).
    """
    p = np.asarray(points, float)
    ang = segment_angles(p)
    radii = turn_radii(p) if len(p) > 2 else np.array([math.inf])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    return {'max_climb_deg': float(max(0.0, ang.max())),
            'max_dive_deg': float(max(0.0, -ang.min())),
            'min_turn_radius_m': float(radii.min()),
            'spacing_ratio': float(seg.max() / seg.min()) if seg.min() > 0 else math.inf}


def check_limits(points: ArrayLike, limits: Limits, tol: float = CHECK_TOL) -> bool:
    """Return whether the path respects the limits (angles within tol [deg], radius rel.)."""
    got = flight_limits(points)
    return (got['max_climb_deg'] <= limits.max_climb_deg + tol
            and got['max_dive_deg'] <= limits.max_dive_deg + tol
            and got['min_turn_radius_m'] >= limits.min_turn_radius_m * (1.0 - tol))


class LimitConstraints:
    """The limits as smooth inequalities g(z) >= 0 over a path's interior vertices.

    Parameters
    ----------
    start, goal : ndarray, shape (3,)
        Fixed end points [m].
    limits : Limits
        The limits, enforced with a small margin so the result passes :func:`check_limits`.
    seg_ref : float
        Reference segment length [m]: every segment must lie in
        [seg_ref / spacing, seg_ref * spacing] (keeps the turn-radius rule meaningful);
        also the scale that makes every g of order one.
    spacing : float
        Allowed spread of segment lengths around seg_ref.

    Notes
    -----
    Climb: ``tan(max_climb) h - dz >= 0``, dive: ``tan(max_dive) h + dz >= 0`` with h the
    horizontal length; turn: ``1 - (R_min / R)^2 >= 0`` with ``R = |u - v| / (2 sin t)``
    (law of sines; u, v the vertex's two sides, t the angle between them). The Jacobian is
    by complex step: each g depends on at most three consecutive vertices, so nine complex
    evaluations (vertices taken three apart, one coordinate at a time) give it exactly.
    """

    def __init__(self, start: NDArray, goal: NDArray, limits: Limits, seg_ref: float,
                 spacing: float = 1.5) -> None:
        self.start = np.asarray(start, float)
        self.goal = np.asarray(goal, float)
        self.seg_ref = float(seg_ref)
        self.spacing = float(spacing)
        climb = min(limits.max_climb_deg - 1e-3, 89.9)
        dive = min(limits.max_dive_deg - 1e-3, 89.9)
        self.tan_climb = math.tan(math.radians(climb))
        self.tan_dive = math.tan(math.radians(dive))
        self.r_min = limits.min_turn_radius_m * (1.0 + 1e-5)

    def _points(self, z: NDArray) -> NDArray:
        return np.vstack([self.start[None, :].astype(z.dtype), z.reshape(-1, 3),
                          self.goal[None, :].astype(z.dtype)])

    def _g(self, p: NDArray) -> NDArray:
        """Constraint values of points p (real or complex), scaled to order one."""
        d = p[1:] - p[:-1]
        s = self.seg_ref
        h = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2 + (1e-9 * s) ** 2)
        length = np.sqrt(np.sum(d * d, axis=1))
        parts = [(self.tan_climb * h - d[:, 2]) / s, (self.tan_dive * h + d[:, 2]) / s,
                 (length - s / self.spacing) / s, (s * self.spacing - length) / s]
        if len(p) > 2 and self.r_min > 0:
            u = p[:-2] - p[1:-1]
            v = p[2:] - p[1:-1]
            cr = np.cross(u, v)
            uu, vv = np.sum(u * u, axis=1), np.sum(v * v, axis=1)
            ww = np.sum((u - v) ** 2, axis=1)
            # (R_min / R)^2 = 4 R_min^2 sin^2 t / |u - v|^2, sin^2 t = |u x v|^2 / (uu vv)
            # A tiny floor keeps coincident vertices (met in line searches) from giving NaN.
            den = uu * vv * ww + (1e-12 * s) ** 6
            parts.append(1.0 - 4.0 * self.r_min ** 2 * np.sum(cr * cr, axis=1) / den)
        return np.concatenate(parts)

    def __call__(self, z: NDArray) -> NDArray:
        """Return g(z) (>= 0 where the limits hold)."""
        return self._g(self._points(np.asarray(z, float)))

    def jacobian(self, z: NDArray) -> NDArray:
        """Return dg/dz, shape (len(g), len(z)), by complex step."""
        z = np.asarray(z, float)
        m = len(z) // 3
        n_seg = m + 1
        # Full-path vertex indices each constraint depends on (-1: none).
        seg_dep = np.stack([np.arange(n_seg), np.arange(1, n_seg + 1),
                            np.full(n_seg, -1)], axis=1)
        deps = [seg_dep] * 4
        if m >= 1 and self.r_min > 0:
            v = np.arange(1, m + 1)
            deps.append(np.stack([v - 1, v, v + 1], axis=1))
        deps = np.vstack(deps)
        interior = (deps >= 1) & (deps <= m)
        jac = np.zeros((len(deps), len(z)))
        rows = np.arange(len(deps))
        for r in range(3):
            hit = interior & ((deps - 1) % 3 == r)
            # Exactly one of a constraint's (up to three) consecutive vertices is hit.
            k = np.argmax(hit, axis=1)
            has = hit[rows, k]
            vert = deps[rows, k]
            for c in range(3):
                zc = z.astype(complex)
                zc[3 * np.arange(r, m, 3) + c] += 1j * _CSTEP
                g = self._g(self._points(zc)).imag / _CSTEP
                cols = 3 * (vert[has] - 1) + c
                jac[rows[has], cols] = g[has]
        return jac
