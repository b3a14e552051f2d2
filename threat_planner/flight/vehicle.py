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
from numpy.typing import NDArray

from threat_planner.core.flight.reference import ReferencePath

__all__ = ['PointMass', 'ReferencePath', 'TURN_MARGIN']

#: The vehicle turns on circles this much wider than the limit.
TURN_MARGIN = 1.002


def _unit(v: NDArray) -> NDArray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


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
