"""The simulated vehicle: a point mass at constant speed, turning and climbing in limits.

Each step it steers its velocity towards a look-ahead point of the path it follows (pure
pursuit), turning at most ``speed / R * dt`` [rad] (R the turn radius limit, widened by
TURN_MARGIN so that the polyline of its positions passes the fillet rule of
:mod:`threat_planner.core.optimise.limits`, whose sampled circle of radius R reads a
hair below R), with its flight-path angle held within the climb and dive limits: it
aims at the target's direction clamped to them, along the great circle where that stays
within them, else about the vertical at its flight-path angle.
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
        self.heading = self._turn(self.heading, self._in_band(want, self.heading), dt)
        self.position = self.position + self.speed * dt * self.heading

    def _band(self) -> tuple[float, float]:
        return -math.radians(self.max_dive_deg), math.radians(self.max_climb_deg)

    def _in_band(self, d: NDArray, h: NDArray) -> NDArray:
        """Return `d` with its flight-path angle clamped to the limits.

        Its azimuth is kept (the current heading's where `d` is vertical).
        """
        lo, hi = self._band()
        flat = d[:2] if math.hypot(d[0], d[1]) > 1e-12 else h[:2]
        if math.hypot(flat[0], flat[1]) <= 1e-12:
            flat = np.array([1.0, 0.0])
        flat = flat / math.hypot(flat[0], flat[1])
        pitch = min(max(math.atan2(d[2], math.hypot(d[0], d[1])), lo), hi)
        return np.array([flat[0] * math.cos(pitch), flat[1] * math.cos(pitch),
                         math.sin(pitch)])

    def _turn(self, h: NDArray, want: NDArray, dt: float) -> NDArray:
        """Turn unit `h` towards `want` by at most ``speed dt / (R TURN_MARGIN)``.

        `want` is within the climb and dive limits, and so is every heading. Along the
        great circle first; where that circle bulges past a limit (a turn at a steep
        climb limit goes over the pole), at the flight-path angle the heading has, about
        the vertical, by the angle that turns it as far.
        """
        if self.min_turn_radius_m <= 0:
            return want
        most = self.speed * dt / (self.min_turn_radius_m * TURN_MARGIN)
        angle = math.acos(float(np.clip(h @ want, -1.0, 1.0)))
        if angle <= most:
            return want
        side = want - (h @ want) * h
        if np.linalg.norm(side) < 1e-12:   # straight behind: turn level, either way
            side = np.cross([0.0, 0.0, 1.0], h)
            if np.linalg.norm(side) < 1e-12:
                side = np.array([1.0, 0.0, 0.0])
        side = _unit(side - (side @ h) * h)
        turned = math.cos(most) * h + math.sin(most) * side
        lo, hi = self._band()
        if lo - 1e-12 <= math.asin(float(np.clip(turned[2], -1.0, 1.0))) <= hi + 1e-12:
            return turned
        pitch = min(max(math.asin(float(np.clip(h[2], -1.0, 1.0))), lo), hi)
        c = math.cos(pitch)
        # Turning about the vertical by b at flight-path angle p moves the heading by
        # 2 asin(cos p sin(b / 2)): the most b within `most`, and no further than `want`.
        b = math.pi if c <= math.sin(most / 2) else 2 * math.asin(math.sin(most / 2) / c)
        az_h, az_w = math.atan2(h[1], h[0]), math.atan2(want[1], want[0])
        gap = (az_w - az_h + math.pi) % (2 * math.pi) - math.pi
        az = az_h + math.copysign(min(b, abs(gap)), gap)
        return np.array([c * math.cos(az), c * math.sin(az), math.sin(pitch)])
