"""No-fly zones: sphere, vertical cylinder, box and prism, with exact signed distances.

Every zone is an open set: a path may touch its boundary but not enter it. Each zone gives
its signed distance (negative inside, exact) and its gradient. The cylinder, box and prism
are vertical extrusions of a 2-D shape, and for those the signed distance is the
extrusion formula ``min(max(d2, dz), 0) + |max((d2, dz), 0)|`` with d2 the shape's 2-D
signed distance and dz the signed distance to the slab z_min..z_max, exact for any shape.

The smallest distance of a segment to a convex zone is a convex function of the segment's
parameter, found by golden-section search; the prism is split into triangles (ear
clipping) and the segment's distance is the smallest over those convex pieces, exact
outside. Whether a segment enters a prism is decided exactly from its crossings with the
polygon's edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ['Sphere', 'Cylinder', 'BoxZone', 'Prism', 'Zone', 'segment_distance']

#: Golden-section steps: the bracket shrinks to 0.618^60 ~ 3e-13 of the segment.
GOLDEN_STEPS = 60
_PHI = (np.sqrt(5.0) - 1.0) / 2.0
#: Samples of a segment that enters a prism, to report how deep it goes.
PRISM_DEPTH_SAMPLES = 1025
#: The central differences' unit steps: +x, +y, +z, -x, -y, -z.
_UNIT_STEPS = np.concatenate([np.eye(3), -np.eye(3)])


def _extrude(d2: NDArray, z: NDArray, z_min: float, z_max: float
             ) -> tuple[NDArray, NDArray]:
    """Combine a 2-D signed distance with the slab's; return (sdf, which: 0 = 2-D, 1 = z)."""
    dz = np.maximum(z_min - z, z - z_max)
    outside = np.hypot(np.maximum(d2, 0.0), np.maximum(dz, 0.0))
    return np.minimum(np.maximum(d2, dz), 0.0) + outside, dz


class Zone:
    """Base of the zone types: name, signed distance, gradient, segment distance."""

    kind = 'zone'
    convex = True
    label = ''

    def sdf(self, p: NDArray) -> NDArray:
        """Signed distance of points (..., 3) to the zone's boundary, < 0 inside [m]."""
        raise NotImplementedError

    def sdf_grad(self, p: NDArray) -> NDArray:
        """Gradient of sdf at points (..., 3), by central differences of the exact sdf.

        The six shifted copies go to sdf in one call: it works point by point, so the
        values are those of six calls, for one call's numpy overhead (the points are few).
        """
        p = np.asarray(p, float)
        eps = 1e-6 * max(1.0, self.scale)
        steps = _UNIT_STEPS * eps
        vals = self.sdf(p[None] + steps.reshape((6,) + (1,) * (p.ndim - 1) + (3,)))
        return np.moveaxis((vals[:3] - vals[3:]) / (2 * eps), 0, -1)

    @property
    def scale(self) -> float:
        """Typical size [m] (for finite-difference steps)."""
        return 1.0

    def inside(self, p: NDArray) -> NDArray:
        """Return whether each point (last axis xyz) lies in the open interior."""
        return self.sdf(np.asarray(p, float)) < 0.0

    def segment_distance(self, a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
        """Smallest signed distance along segments a->b (S, 3), and its parameter."""
        return segment_distance(self, a, b)

    def enters(self, a: NDArray, b: NDArray, tol: float = 0.0) -> NDArray:
        """Whether segments a->b enter the open zone (deeper than tol [m])."""
        return self.segment_distance(a, b)[0] < -tol


def _golden(f, lo: NDArray, hi: NDArray) -> tuple[NDArray, NDArray]:
    """Vectorised golden-section minimisation of convex f over [lo, hi].

    Each step keeps one of its two points and evaluates f once, at the new one of each
    segment (f works point by point: the values are those of evaluating both).
    """
    x1 = hi - _PHI * (hi - lo)
    x2 = lo + _PHI * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(GOLDEN_STEPS):
        left = f1 < f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        # Left: the old x1 becomes x2 and x1 is new; else the old x2 becomes x1.
        x1, x2 = (np.where(left, hi - _PHI * (hi - lo), x2),
                  np.where(left, x1, lo + _PHI * (hi - lo)))
        fresh = f(np.where(left, x1, x2))
        f1, f2 = np.where(left, fresh, f2), np.where(left, f1, fresh)
    t = 0.5 * (lo + hi)
    return f(t), t


def segment_distance(zone: Zone, a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
    """Smallest signed distance of each segment a->b to a zone, and its parameter [0, 1].

    Exact (to 3e-13 of the segment) for convex zones; for a prism, the smallest over its
    convex pieces outside, and a golden-section estimate of the depth inside.
    """
    a = np.atleast_2d(np.asarray(a, float))
    b = np.atleast_2d(np.asarray(b, float))
    d = b - a
    pieces = zone.pieces() if isinstance(zone, Prism) else [zone]
    best = np.full(len(a), np.inf)
    where = np.zeros(len(a))
    for piece in pieces:
        val, t = _golden(lambda t: piece.sdf(a + t[:, None] * d),
                         np.zeros(len(a)), np.ones(len(a)))
        # The ends too: golden section never evaluates exactly at 0 or 1.
        for end in (0.0, 1.0):
            v = piece.sdf(a + end * d)
            better = v < val
            val, t = np.where(better, v, val), np.where(better, end, t)
        better = val < best
        best, where = np.where(better, val, best), np.where(better, t, where)
    if isinstance(zone, Prism):
        # Inside, the union is deeper than any one piece says (and a segment along a
        # shared diagonal reads 0): estimate the depth from dense samples of the exact sdf.
        deep = zone.crosses(a, b)
        if np.any(deep):
            t = np.linspace(0.0, 1.0, PRISM_DEPTH_SAMPLES)
            vals = zone.sdf(a[deep][:, None] + t[None, :, None] * d[deep][:, None])
            k = np.argmin(vals, axis=1)
            best[deep] = np.minimum(vals[np.arange(len(k)), k], -1e-12)
            where[deep] = t[k]
    return best, where


@dataclass(frozen=True)
class Sphere(Zone):
    """Ball of ``radius`` [m] around ``center`` (3,) [m]."""

    center: NDArray
    radius: float
    label: str = 'sphere'
    kind = 'sphere'

    @property
    def scale(self) -> float:  # noqa: D102
        return float(self.radius)

    def sdf(self, p: NDArray) -> NDArray:  # noqa: D102
        return np.linalg.norm(np.asarray(p, float) - self.center, axis=-1) - self.radius

    def sdf_grad(self, p: NDArray) -> NDArray:  # noqa: D102
        v = np.asarray(p, float) - self.center
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        return v / np.where(n > 0, n, 1.0)


@dataclass(frozen=True)
class Cylinder(Zone):
    """Vertical cylinder: disc of ``radius`` [m] around ``center`` (x, y), z_min..z_max."""

    center: NDArray
    radius: float
    z_min: float
    z_max: float
    label: str = 'cylinder'
    kind = 'cylinder'

    @property
    def scale(self) -> float:  # noqa: D102
        return float(max(self.radius, self.z_max - self.z_min))

    def sdf(self, p: NDArray) -> NDArray:  # noqa: D102
        p = np.asarray(p, float)
        d2 = np.linalg.norm(p[..., :2] - self.center, axis=-1) - self.radius
        return _extrude(d2, p[..., 2], self.z_min, self.z_max)[0]


@dataclass(frozen=True)
class BoxZone(Zone):
    """Axis-aligned box from ``lo`` (3,) to ``hi`` (3,) [m]."""

    lo: NDArray
    hi: NDArray
    label: str = 'box'
    kind = 'box'

    @property
    def scale(self) -> float:  # noqa: D102
        return float(np.max(self.hi - self.lo))

    def sdf(self, p: NDArray) -> NDArray:  # noqa: D102
        p = np.asarray(p, float)
        c, h = 0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo)
        q = np.abs(p - c) - h
        return (np.linalg.norm(np.maximum(q, 0.0), axis=-1)
                + np.minimum(np.max(q, axis=-1), 0.0))


def _polygon_sdf(xy: NDArray, poly: NDArray) -> NDArray:
    """Signed 2-D distance of points (..., 2) to a simple polygon (V, 2), < 0 inside."""
    # By components, (..., V) arrays only: the operations of the (..., V, 2) form, element
    # by element (a sum or norm over 2 is x0 + x1), at a third of its time.
    ax, ay = poly[:, 0], poly[:, 1]
    e = np.roll(poly, -1, axis=0) - poly
    ex, ey = e[:, 0], e[:, 1]
    x, y = xy[..., 0, None], xy[..., 1, None]
    rx, ry = x - ax, y - ay                                # (..., V)
    t = np.clip((rx * ex + ry * ey) / (ex * ex + ey * ey), 0.0, 1.0)
    dx, dy = rx - t * ex, ry - t * ey
    dist = np.sqrt(dx * dx + dy * dy).min(axis=-1)
    # Even-odd rule for inside; points on an edge have distance 0 either way.
    cond = (ay > y) != (ay + ey > y)
    with np.errstate(divide='ignore', invalid='ignore'):
        x_cross = ax + (y - ay) * ex / ey
    inside = (np.sum(cond & (x < x_cross), axis=-1) % 2) == 1
    return np.where(inside, -dist, dist)


def _ear_clip(poly: NDArray) -> list[NDArray]:
    """Triangles (3, 2) of a simple polygon, counter-clockwise."""
    pts = [p for p in poly]
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1)
                        * poly[:, 1])
    if area < 0:
        pts = pts[::-1]
    tris = []

    def cross(o, p, q):
        return (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])

    while len(pts) > 3:
        for i in range(len(pts)):
            p, q, r = pts[i - 1], pts[i], pts[(i + 1) % len(pts)]
            if cross(p, q, r) <= 0:
                continue
            others = [s for j, s in enumerate(pts)
                      if j not in (i - 1 if i else len(pts) - 1, i, (i + 1) % len(pts))]
            if any(cross(p, q, s) >= 0 and cross(q, r, s) >= 0 and cross(r, p, s) >= 0
                   for s in others):
                continue
            tris.append(np.array([p, q, r]))
            del pts[i]
            break
        else:   # only collinear vertices left: nothing of positive area remains
            break
    if len(pts) == 3 and cross(*pts) > 0:
        tris.append(np.array(pts))
    return tris


@dataclass(frozen=True)
class Prism(Zone):
    """Vertical extrusion of a simple polygon (V, 2) [m] from z_min to z_max [m]."""

    polygon: NDArray
    z_min: float
    z_max: float
    label: str = 'prism'
    kind = 'prism'
    convex = False

    @property
    def scale(self) -> float:  # noqa: D102
        return float(max(np.ptp(self.polygon, axis=0).max(), self.z_max - self.z_min))

    def sdf(self, p: NDArray) -> NDArray:  # noqa: D102
        p = np.asarray(p, float)
        return _extrude(_polygon_sdf(p[..., :2], self.polygon), p[..., 2], self.z_min,
                        self.z_max)[0]

    def pieces(self) -> list['Prism']:
        """Convex triangular prisms whose union is this prism."""
        cached = self.__dict__.get('_pieces')
        if cached is None:
            cached = [Prism(t, self.z_min, self.z_max, self.label)
                      for t in _ear_clip(self.polygon)]
            object.__setattr__(self, '_pieces', cached)
        return cached

    def crosses(self, a: NDArray, b: NDArray) -> NDArray:
        """Exactly whether segments a->b (S, 3) pass through the prism's open interior.

        The part of each segment inside the slab z_min < z < z_max is split where its
        ground track crosses polygon edges; each piece lies wholly inside or outside the
        polygon, so testing the pieces' midpoints decides.
        """
        a, b = np.atleast_2d(a), np.atleast_2d(b)
        out = np.zeros(len(a), bool)
        poly = self.polygon
        lo_xy, hi_xy = poly.min(axis=0), poly.max(axis=0)
        near = ((np.minimum(a[:, :2], b[:, :2]) < hi_xy).all(axis=1)
                & (np.maximum(a[:, :2], b[:, :2]) > lo_xy).all(axis=1)
                & (np.minimum(a[:, 2], b[:, 2]) < self.z_max)
                & (np.maximum(a[:, 2], b[:, 2]) > self.z_min))
        if not near.any():
            return out
        pa, pb = a[near], b[near]
        dz = pb[:, 2] - pa[:, 2]
        flat = dz == 0
        with np.errstate(divide='ignore', invalid='ignore'):
            t0 = (self.z_min - pa[:, 2]) / dz
            t1 = (self.z_max - pa[:, 2]) / dz
        lo = np.where(flat, 0.0, np.maximum(np.minimum(t0, t1), 0.0))
        hi = np.where(flat, 1.0, np.minimum(np.maximum(t0, t1), 1.0))
        in_slab = np.where(flat, (self.z_min < pa[:, 2]) & (pa[:, 2] < self.z_max), hi > lo)
        d = pb[:, :2] - pa[:, :2]
        e = np.roll(poly, -1, axis=0) - poly
        rel = poly[None] - pa[:, None, :2]                        # (S, V, 2)
        den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
        with np.errstate(divide='ignore', invalid='ignore'):
            tt = (rel[..., 0] * e[None, :, 1] - rel[..., 1] * e[None, :, 0]) / den
            uu = (rel[..., 0] * d[:, None, 1] - rel[..., 1] * d[:, None, 0]) / den
        ok = np.isfinite(tt) & (uu >= 0) & (uu <= 1) & (tt > lo[:, None]) & (tt < hi[:, None])
        ts = np.sort(np.concatenate([lo[:, None], np.where(ok, tt, hi[:, None]),
                                     hi[:, None]], axis=1), axis=1)
        mids = 0.5 * (ts[:, :-1] + ts[:, 1:])
        real = ts[:, 1:] > ts[:, :-1]
        real[:, 0] |= ~real.any(axis=1)       # a ground track that is a single point
        pts = pa[:, None, :2] + mids[..., None] * d[:, None, :]
        inside = (_polygon_sdf(pts, poly) < 0) & real
        out[near] = in_slab & inside.any(axis=1)
        return out


def polygon_is_simple(poly: NDArray) -> tuple[bool, str]:
    """Whether a polygon (V, 2) is simple (no two non-adjacent edges meet), with reason."""
    n = len(poly)
    if n < 3:
        return False, f'needs at least 3 vertices, got {n}'
    area = 0.5 * abs(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1)
                            - np.roll(poly[:, 0], -1) * poly[:, 1]))
    if area <= 0:
        return False, 'has zero area'
    q = np.roll(poly, -1, axis=0)

    def orient(p, r, s):
        v = (r[0] - p[0]) * (s[1] - p[1]) - (r[1] - p[1]) * (s[0] - p[0])
        return np.sign(v)

    def on(p, r, s):
        return (min(p[0], r[0]) <= s[0] <= max(p[0], r[0])
                and min(p[1], r[1]) <= s[1] <= max(p[1], r[1]))

    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                if np.allclose(poly[i], poly[j]):
                    return False, f'vertices {i} and {j} coincide'
                continue
            p1, p2, p3, p4 = poly[i], q[i], poly[j], q[j]
            o1, o2 = orient(p1, p2, p3), orient(p1, p2, p4)
            o3, o4 = orient(p3, p4, p1), orient(p3, p4, p2)
            meet = ((o1 != o2 and o3 != o4) or (o1 == 0 and on(p1, p2, p3))
                    or (o2 == 0 and on(p1, p2, p4)) or (o3 == 0 and on(p3, p4, p1))
                    or (o4 == 0 and on(p3, p4, p2)))
            if meet:
                return False, f'edges {i} and {j} intersect'
    return True, ''
