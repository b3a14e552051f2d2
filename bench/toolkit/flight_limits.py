"""Physical flight limits of a polyline: the definitions, a checker and smooth constraints.

The definitions (the ones the product will adopt):

* **climb / dive angle** of a segment = ``atan2(+-dz, horizontal length)``; the climb angle
  (dz > 0) must be <= ``max_climb_deg`` and the dive angle (dz < 0) <= ``max_dive_deg``.
* **turn radius** at an interior vertex = radius of the arc tangent to both of its
  segments whose tangent points lie within the vertex's share of each (half a segment,
  all of the first and last one): ``share / tan(theta / 2)`` with theta the turn angle in
  3-D (straight on: infinite, straight back: 0); it must be >= ``min_turn_radius_m``.

:func:`flight_limits` and :func:`check_limits` evaluate these directly (the turn angle by
``arctan2(|u x v|, u . v)``, no optimiser code), so they are an independent check of what
:class:`LimitConstraints` enforces inside the optimiser. The radius of the circle through
three points, the rule before, could not see a reversal beside a short segment; the
fillet can (a hairpin has radius 0 whatever the segment lengths).
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
    """Fillet radius at each interior vertex [m]: share / tan(theta / 2).

    theta = arctan2(|a x b|, a . b) for the segments a, b meeting there; the share is half
    of each segment, all of the first and last. Coincident points give ``inf``.
    """
    p = np.asarray(points, float)
    d = np.diff(p, axis=0)
    seg = np.linalg.norm(d, axis=1)
    share = seg / 2.0
    share[0], share[-1] = seg[0], seg[-1]
    a, b = d[:-1], d[1:]
    theta = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))
    with np.errstate(divide='ignore', invalid='ignore'):
        r = np.minimum(share[:-1], share[1:]) / np.tan(theta / 2.0)
    # tan(pi / 2) is finite in floating point: a hairpin is exactly 0.
    r = np.where(theta >= math.pi * (1 - 1e-15), 0.0, r)
    return np.where((seg[:-1] == 0) | (seg[1:] == 0), np.inf, r)


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
    horizontal length; turn: two rows a vertex, ``cos(theta) - (1 - t^2) / (1 + t^2) >= 0``
    with t = share / R_min for the share of the segment before and after it (this is
    tan(theta / 2) <= t, the fillet fitting). The Jacobian is
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
            a, b = d[:-1], d[1:]
            # A tiny floor keeps coincident vertices (met in line searches) from giving NaN.
            la = np.sqrt(np.sum(a * a, axis=1) + (1e-12 * s) ** 2)
            lb = np.sqrt(np.sum(b * b, axis=1) + (1e-12 * s) ** 2)
            cos = np.sum(a * b, axis=1) / (la * lb)
            alpha = np.full(len(d), 0.5)
            alpha[0] = alpha[-1] = 1.0
            for share in (alpha[:-1] * la, alpha[1:] * lb):
                t2 = (share / self.r_min) ** 2
                parts.append(cos - (1.0 - t2) / (1.0 + t2))
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
            deps += [np.stack([v - 1, v, v + 1], axis=1)] * 2
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
