"""A path by arc length: where a point at arc length s is, the piece between two, nearest s.

The fly loop's vehicle follows one (:mod:`threat_planner.flight.vehicle`) and a replan in
flight cuts its committed stretch from one (:mod:`.commit`); both read the same numbers.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['DUPLICATE_M', 'ReferencePath', 'distinct']

#: Consecutive points closer than this are one point [m].
DUPLICATE_M = 1e-9


def _unit(v: NDArray) -> NDArray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def distinct(points: NDArray) -> NDArray:
    """Return the indices of the points kept: each farther than DUPLICATE_M from the one before.

    A polyline of fewer than two distinct points keeps its two ends.
    """
    keep = np.ones(len(points), bool)
    keep[1:] = np.linalg.norm(np.diff(points, axis=0), axis=1) > DUPLICATE_M
    return np.flatnonzero(keep) if keep.sum() >= 2 else np.array([0, len(points) - 1])


class ReferencePath:
    """A polyline with arc length, for following: points, cumulative lengths [m]."""

    def __init__(self, points: ArrayLike) -> None:
        pts = np.asarray(points, float).reshape(-1, 3)
        self.points = pts[distinct(pts)]
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

    def inner(self, s0: float, s1: float) -> NDArray:
        """Return the mask of the vertices strictly between arc lengths s0 and s1."""
        return (self.s > s0) & (self.s < s1)

    def piece(self, s0: float, s1: float) -> NDArray:
        """Return the polyline between arc lengths s0 < s1, ends included."""
        inner = self.points[self.inner(s0, s1)]
        return np.vstack([self.at(s0)[None], inner, self.at(s1)[None]])
