"""The simulated vehicle: a point mass at constant speed, turning and climbing in limits.

Each step it steers its velocity towards a look-ahead point of the path it follows (pure
pursuit), turning at most ``speed / R * dt`` [rad] (R the turn radius limit, widened by
TURN_MARGIN so that the polyline of its positions passes the fillet rule of
:mod:`threat_planner.core.optimise.limits`, whose sampled circle of radius R reads a
hair below R), with its flight-path angle held within the climb and dive limits.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['PointMass', 'ReferencePath', 'TURN_MARGIN']

#: The vehicle turns on circles this much wider than the limit.
TURN_MARGIN = 1.002


def _unit(v: NDArray) -> NDArray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


class ReferencePath:
    """A polyline with arc length, for following: points, cumulative lengths [m]."""

    def __init__(self, points: ArrayLike) -> None:
        pts = np.asarray(points, float).reshape(-1, 3)
        keep = np.ones(len(pts), bool)
        keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9
        self.points = pts[keep] if keep.sum() >= 2 else pts[[0, -1]]
        self.s = np.concatenate([[0.0], np.cumsum(
            np.linalg.norm(np.diff(self.points, axis=0), axis=1))])

    @property
    def length(self) -> float:
        """Total length [m]."""
        return float(self.s[-1])

    def at(self, s: float | NDArray) -> NDArray:
        """Point(s) at arc length `s` [m], clamped to the ends."""
        s = np.clip(np.asarray(s, float), 0.0, self.length)
        return np.stack([np.interp(s, self.s, self.points[:, k]) for k in range(3)], -1)

    def ahead(self, s: float) -> NDArray:
        """Point at arc length `s`, past the end along the last segment.

        A pursuer aiming at the goal itself circles it once the goal is inside its turn
        circle; aiming past it along the path's last direction, it flies through it.
        """
        if s <= self.length:
            return self.at(s)
        return self.points[-1] + (s - self.length) * self.tangent(self.length)

    def tangent(self, s: float) -> NDArray:
        """Return the unit direction of the segment at arc length `s`."""
        k = int(np.clip(np.searchsorted(self.s, s, side='right') - 1, 0, len(self.s) - 2))
        return _unit(self.points[k + 1] - self.points[k])

    def project(self, p: NDArray, lo: float, hi: float) -> float:
        """Arc length of the point nearest `p` with arc length in [lo, hi] [m]."""
        a, b = self.points[:-1], self.points[1:]
        d = b - a
        l2 = np.maximum(np.einsum('ij,ij->i', d, d), 1e-300)
        u = np.clip(np.einsum('ij,ij->i', p - a, d) / l2, 0.0, 1.0)
        s = np.clip(self.s[:-1] + u * np.sqrt(l2), lo, hi)
        dist = np.linalg.norm(self.at(s) - p, axis=1)
        return float(s[int(np.argmin(dist))])

    def piece(self, s0: float, s1: float) -> NDArray:
        """Return the polyline between arc lengths s0 < s1, ends included."""
        inner = self.points[(self.s > s0) & (self.s < s1)]
        return np.vstack([self.at(s0)[None], inner, self.at(s1)[None]])


@dataclass
class PointMass:
    """A point mass at constant speed (module docstring).

    Attributes
    ----------
    position : NDArray
        (3,) [m].
    heading : NDArray
        (3,) unit velocity direction.
    speed : float
        [m/s].
    min_turn_radius_m, max_climb_deg, max_dive_deg : float
        Its limits (0 / 90 / 90 = none).

    """

    position: NDArray
    heading: NDArray
    speed: float
    min_turn_radius_m: float = 0.0
    max_climb_deg: float = 90.0
    max_dive_deg: float = 90.0

    def step(self, target: NDArray, dt: float) -> None:
        """Fly `dt` [s] steering towards `target` (3,) [m]."""
        want = _unit(np.asarray(target, float) - self.position)
        if not np.any(want):
            want = self.heading
        h = self._turn(self.heading, want, dt)
        h = self._clamp_pitch(h, want)
        self.heading = h
        self.position = self.position + self.speed * dt * h

    def _turn(self, h: NDArray, want: NDArray, dt: float) -> NDArray:
        if self.min_turn_radius_m <= 0:
            return want
        most = self.speed * dt / (self.min_turn_radius_m * TURN_MARGIN)
        angle = math.acos(float(np.clip(h @ want, -1.0, 1.0)))
        if angle <= most:
            return want
        axis = np.cross(h, want)
        if np.linalg.norm(axis) < 1e-12:   # straight behind: turn about the vertical
            axis = np.cross(h, [0.0, 0.0, 1.0])
            if np.linalg.norm(axis) < 1e-12:
                axis = np.array([1.0, 0.0, 0.0])
            axis = np.cross(axis, h)
        axis = _unit(axis)
        # Rodrigues' rotation of h about axis by `most`.
        return _unit(h * math.cos(most) + np.cross(axis, h) * math.sin(most)
                     + axis * (axis @ h) * (1 - math.cos(most)))

    def _clamp_pitch(self, h: NDArray, want: NDArray) -> NDArray:
        horizontal = math.hypot(h[0], h[1])
        pitch = math.atan2(h[2], horizontal)
        lo, hi = -math.radians(self.max_dive_deg), math.radians(self.max_climb_deg)
        if lo <= pitch <= hi:
            return h
        pitch = min(max(pitch, lo), hi)
        flat = h[:2] if horizontal > 1e-12 else want[:2]
        flat = flat / max(float(np.linalg.norm(flat)), 1e-300)
        return np.array([flat[0] * math.cos(pitch), flat[1] * math.cos(pitch),
                         math.sin(pitch)])
