"""Terrain: a height grid, bilinear between grid points, clamped at the grid's edges.

Along any straight line the bilinear height is a quadratic in the line's parameter inside
each grid cell (x and y are linear in it), and clamping only adds the grid's own lines as
breakpoints. So the smallest height of a segment above the terrain is found exactly: split
the segment where it crosses grid lines and take each piece's quadratic minimum. The same
routine decides line of sight (a sight line is clear when it never dips below the ground).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.errors import InputError

__all__ = ['Terrain']

#: Sight lines may graze the ground by this much and still count as clear [m].
GRAZE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Terrain:
    """Height grid with clearance and masking settings.

    Attributes:
        origin: World x, y of grid point (0, 0) [m].
        resolution: Spacing of grid points [m].
        heights: Heights (rows along y, columns along x) [m].
        clearance: Smallest height above the terrain allowed [m].
        masking: Whether the terrain hides the UAV from radars.
    """

    origin: NDArray
    resolution: float
    heights: NDArray
    clearance: float = 0.0
    masking: bool = False

    @classmethod
    def from_arrays(cls, origin: ArrayLike, resolution: float, heights: ArrayLike,
                    clearance: float = 0.0, masking: bool = False) -> 'Terrain':
        """Validate and build a terrain; errors name the field (``terrain.heights`` ...)."""
        try:
            o = np.asarray(origin, float).reshape(-1)
            h = np.asarray(heights, float)
            res = float(resolution)
            clr = float(clearance)
        except (TypeError, ValueError) as exc:
            raise InputError(f'terrain: not numeric ({exc})') from None
        if o.shape != (2,) or not np.all(np.isfinite(o)):
            raise InputError(f'terrain.origin: expected finite [x0, y0], got {o.tolist()}')
        if not np.isfinite(res) or res <= 0:
            raise InputError(f'terrain.resolution: must be positive, got {res}')
        if not np.isfinite(clr) or clr < 0:
            raise InputError(f'terrain.clearance: must be >= 0, got {clr}')
        if h.ndim != 2 or h.shape[0] < 2 or h.shape[1] < 2:
            raise InputError(f'terrain.heights: expected a grid of at least 2 x 2, '
                             f'got shape {list(h.shape)}')
        bad = ~np.isfinite(h)
        if bad.any():
            r, c = (int(v) for v in np.argwhere(bad)[0])
            raise InputError(f'terrain.heights[{r}][{c}]: not finite ({float(h[r, c])}); '
                             f'{int(bad.sum())} bad entries')
        if not isinstance(masking, (bool, np.bool_)):
            raise InputError(f'terrain.masking: expected true or false, got {masking!r}')
        h = h.copy()
        h.setflags(write=False)
        return cls(o, res, h, clr, bool(masking))

    @property
    def extent(self) -> tuple[NDArray, NDArray]:
        """World (x, y) of the first and last grid points [m]."""
        ny, nx = self.heights.shape
        return self.origin, self.origin + self.resolution * np.array([nx - 1, ny - 1])

    def height(self, xy: ArrayLike) -> NDArray:
        """Bilinear terrain height at world points (..., 2) [m], clamped at the edges."""
        xy = np.asarray(xy, float)
        ny, nx = self.heights.shape
        gx = np.clip((xy[..., 0] - self.origin[0]) / self.resolution, 0.0, nx - 1.0)
        gy = np.clip((xy[..., 1] - self.origin[1]) / self.resolution, 0.0, ny - 1.0)
        i = np.minimum(np.floor(gx).astype(np.int64), nx - 2)
        j = np.minimum(np.floor(gy).astype(np.int64), ny - 2)
        fx, fy = gx - i, gy - j
        # The four corners by one flat index each (the same entries as h[j, i], ...).
        h, k = self.heights.ravel(), j * nx + i
        return ((1 - fy) * ((1 - fx) * h[k] + fx * h[k + 1])
                + fy * ((1 - fx) * h[k + nx] + fx * h[k + nx + 1]))

    def height_gradient(self, xy: ArrayLike) -> NDArray:
        """Slope (dh/dx, dh/dy) at world points (..., 2); zero across clamped edges."""
        xy = np.asarray(xy, float)
        ny, nx = self.heights.shape
        rx = (xy[..., 0] - self.origin[0]) / self.resolution
        ry = (xy[..., 1] - self.origin[1]) / self.resolution
        gx, gy = np.clip(rx, 0.0, nx - 1.0), np.clip(ry, 0.0, ny - 1.0)
        i = np.minimum(np.floor(gx).astype(np.int64), nx - 2)
        j = np.minimum(np.floor(gy).astype(np.int64), ny - 2)
        fx, fy = gx - i, gy - j
        h = self.heights
        dx = ((1 - fy) * (h[j, i + 1] - h[j, i]) + fy * (h[j + 1, i + 1] - h[j + 1, i]))
        dy = ((1 - fx) * (h[j + 1, i] - h[j, i]) + fx * (h[j + 1, i + 1] - h[j, i + 1]))
        inside_x = (rx > 0) & (rx < nx - 1)
        inside_y = (ry > 0) & (ry < ny - 1)
        return np.stack([dx * inside_x, dy * inside_y], axis=-1) / self.resolution

    @property
    def max_slope(self) -> float:
        """Largest |grad h| anywhere (bounds how fast the height above ground changes)."""
        d = np.abs(np.diff(self.heights, axis=1)).max(initial=0.0)
        e = np.abs(np.diff(self.heights, axis=0)).max(initial=0.0)
        return float(np.hypot(d, e) / self.resolution)

    def _breakpoints(self, a: NDArray, b: NDArray) -> NDArray:
        """Parameters in [0, 1] where segments a->b cross grid lines, sorted, (S, K)."""
        ny, nx = self.heights.shape
        out = [np.zeros((len(a), 1)), np.ones((len(a), 1))]
        for axis, n in ((0, nx), (1, ny)):
            lines = self.origin[axis] + self.resolution * np.arange(n)
            d = (b[:, axis] - a[:, axis])[:, None]
            with np.errstate(divide='ignore', invalid='ignore'):
                s = (lines[None, :] - a[:, axis][:, None]) / d
            s = np.where(np.isfinite(s) & (s > 0) & (s < 1), s, 1.0)
            out.append(s)
        return np.sort(np.concatenate(out, axis=1), axis=1)

    def min_height_above(self, a: ArrayLike, b: ArrayLike) -> tuple[NDArray, NDArray]:
        """Exact smallest z - h(x, y) along each segment a->b, and where it is.

        Args:
            a: Segment starts (S, 3) [m].
            b: Segment ends (S, 3) [m].

        Returns:
            ``(margin (S,) [m], parameter (S,) in [0, 1])``.
        """
        a = np.atleast_2d(np.asarray(a, float))
        b = np.atleast_2d(np.asarray(b, float))
        s = self._breakpoints(a, b)
        lo, hi = s[:, :-1], s[:, 1:]
        mid = 0.5 * (lo + hi)
        # One evaluation at the breakpoints and the middles: a piece's end is the next
        # one's start, and the height works point by point.
        t = np.concatenate([s, mid], axis=1)
        p = a[:, None, :] + t[..., None] * (b - a)[:, None, :]
        ft = p[..., 2] - self.height(p[..., :2])
        k1 = s.shape[1]
        f0, fm, f1 = ft[:, :k1 - 1], ft[:, k1:], ft[:, 1:k1]
        # Quadratic through the three values of each piece; its vertex where inside.
        curv = f0 - 2 * fm + f1
        with np.errstate(divide='ignore', invalid='ignore'):
            u = 0.5 * (f0 - f1) / (2 * curv) + 0.5
        ok = (curv > 0) & (u > 0) & (u < 1)
        u = np.where(ok, u, 0.5)
        fv = np.where(ok, f0 * (1 - u) * (1 - 2 * u) + 4 * fm * u * (1 - u)
                      + f1 * u * (2 * u - 1), np.inf)
        vals = np.stack([f0, f1, fv], axis=-1)
        params = np.stack([lo, hi, lo + u * (hi - lo)], axis=-1)
        flat = vals.reshape(len(a), -1)
        k = np.argmin(flat, axis=1)
        rows = np.arange(len(a))
        return flat[rows, k], params.reshape(len(a), -1)[rows, k]

    def clearance_margin(self, a: ArrayLike, b: ArrayLike) -> NDArray:
        """Smallest height above terrain minus the clearance along each segment (S,) [m]."""
        return self.min_height_above(a, b)[0] - self.clearance

    def visible(self, radar: ArrayLike, points: ArrayLike) -> NDArray:
        """Whether each point sees the radar: the sight line never dips below the ground.

        Args:
            radar: Radar position (3,) [m], or (P, 3) one per point.
            points: UAV positions (P, 3) [m].

        Returns:
            Boolean array (P,).
        """
        points = np.atleast_2d(np.asarray(points, float))
        radar = np.broadcast_to(np.asarray(radar, float), points.shape)
        return self.min_height_above(radar, points)[0] >= -GRAZE_TOLERANCE
