"""DEM terrain: a GeoTIFF (any CRS rasterio reads) resampled onto the ENU grid of a box.

The grid starts at the box's south-west corner (``box.lo`` x, y) and steps ``resolution``
metres east and north until it covers the box (grid lines past the far edges repeat the
edge's heights: they lie outside the box). By default the resolution is the DEM's own
pixel spacing measured in ENU at the box centre, coarsened so that neither side of the
grid has more than :data:`MAX_GRID_POINTS` points.

At each grid point (x, y) the terrain height is the ENU z where the vertical line of the
ENU frame through (x, y) meets the ground: the z whose point has an ellipsoidal height
equal to the DEM's height there. The DEM is read bilinearly between pixel centres (the
outer half of an edge pixel takes that pixel's value); a few fixed-point steps find z
(the ENU vertical leans from the local one by the distance over the earth's radius,
0.9 deg at 100 km, so the DEM is sampled a little away from the point under z = 0).

DEM heights must be metres (a band whose unit says otherwise is refused) and are taken as
heights above the WGS84 ellipsoid; a DEM above the geoid (SRTM, EGM96 / EGM2008 heights)
needs ``height_offset``, the local geoid undulation N (h = H + N). A pixel without data
(the nodata value, a mask or NaN) next to any grid point is an error: the planner would
otherwise fly blind over a hole. rasterio is imported only when a DEM is read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.geo.frames import Datum
from threat_planner.core.world.threats import Box
from threat_planner.errors import InputError

__all__ = ['MAX_GRID_POINTS', 'dem_grid']

#: Most grid points per side of a DEM terrain's grid (the resolution is coarsened to fit).
MAX_GRID_POINTS = 257
#: Fixed-point steps of the height solve; each shrinks the error ~60 times at 100 km.
HEIGHT_STEPS = 8
#: The height solve stops once no grid point moves more than this [m].
HEIGHT_TOLERANCE_M = 1e-4
_METRES = ('', 'm', 'metre', 'meter', 'metres', 'meters')


def _apply(affine, x: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
    """Apply an affine map (a GeoTIFF's pixel <-> CRS transform) applied to arrays of points."""
    a, b, c, d, e, f = tuple(affine)[:6]
    return a * x + b * y + c, d * x + e * y + f


class _Dem:
    """An open GeoTIFF's first band, sampled bilinearly at latitude-longitude points."""

    def __init__(self, ds, name: str) -> None:
        import rasterio.warp
        self.ds, self.name, self._warp = ds, name, rasterio.warp
        if ds.count < 1 or ds.width < 2 or ds.height < 2:
            raise InputError(f'terrain.dem: {name} needs a band of at least 2 x 2 pixels, '
                             f'got {ds.count} bands of {ds.width} x {ds.height}')
        if ds.crs is None:
            raise InputError(f'terrain.dem: {name} has no coordinate reference system')
        unit = (ds.units[0] or '').strip().lower() if ds.units else ''
        if unit not in _METRES:
            raise InputError(f'terrain.dem: {name} gives heights in {unit!r}; metres needed')
        self._inverse = ~ds.transform

    def pixels(self, lat: NDArray, lon: NDArray) -> tuple[NDArray, NDArray]:
        """Fractional column and row of points (pixel (0, 0) spans 0..1 each way)."""
        xs, ys = self._warp.transform('EPSG:4326', self.ds.crs, lon.ravel().tolist(),
                                      lat.ravel().tolist())
        col, row = _apply(self._inverse, np.asarray(xs), np.asarray(ys))
        return col.reshape(lat.shape), row.reshape(lat.shape)

    def covers(self, col: NDArray, row: NDArray) -> NDArray:
        """Whether each pixel position lies within the raster."""
        tol = 1e-9
        return ((col >= -tol) & (col <= self.ds.width + tol) & (row >= -tol)
                & (row <= self.ds.height + tol))

    def sample(self, col: NDArray, row: NDArray, lat: NDArray, lon: NDArray) -> NDArray:
        """Bilinear heights between pixel centres; InputError where data is missing."""
        from rasterio.windows import Window
        h, w = self.ds.height, self.ds.width
        fc = np.clip(col - 0.5, 0.0, w - 1.0)
        fr = np.clip(row - 0.5, 0.0, h - 1.0)
        i = np.minimum(np.floor(fc).astype(np.int64), w - 2)
        j = np.minimum(np.floor(fr).astype(np.int64), h - 2)
        u, v = fc - i, fr - j
        # Only the pixels the grid needs are read (a DEM tile is often far larger).
        c0, r0 = int(i.min()), int(j.min())
        band = self.ds.read(1, masked=True, window=Window(
            c0, r0, int(i.max()) - c0 + 2, int(j.max()) - r0 + 2)).astype(float)
        i, j = i - c0, j - r0
        band = np.ma.masked_invalid(band)
        values = np.ma.getdata(band)
        mask = np.ma.getmaskarray(band)
        corners = [(j, i), (j, i + 1), (j + 1, i), (j + 1, i + 1)]
        missing = np.zeros(col.shape, bool)
        for r, c in corners:
            missing |= mask[r, c]
        if missing.any():
            k = np.unravel_index(int(np.argmax(missing)), missing.shape)
            raise InputError(
                f'terrain.dem: {self.name} has no data (nodata or NaN pixels) next to '
                f'{int(missing.sum())} of the {missing.size} grid points, first at lat '
                f'{lat[k]:.6f}, lon {lon[k]:.6f}; fill the voids first (for example with '
                'gdal_fillnodata.py)')
        return ((1 - v) * ((1 - u) * values[j, i] + u * values[j, i + 1])
                + v * ((1 - u) * values[j + 1, i] + u * values[j + 1, i + 1]))

    def spacing_m(self, datum: Datum, lat: float, lon: float) -> float:
        """Return the DEM's pixel spacing in ENU metres at (lat, lon): the smaller of its two."""
        col, row = self.pixels(np.array([lat]), np.array([lon]))
        c0, r0 = float(np.floor(col[0])) + 0.5, float(np.floor(row[0])) + 0.5
        xs, ys = _apply(self.ds.transform, np.array([c0, c0 + 1, c0]),
                        np.array([r0, r0, r0 + 1]))
        lons, lats = self._warp.transform(self.ds.crs, 'EPSG:4326', list(xs), list(ys))
        p = datum.to_enu(np.column_stack([lats, lons, np.zeros(3)]))
        return float(min(np.linalg.norm(p[1] - p[0]), np.linalg.norm(p[2] - p[0])))

    def extent(self) -> str:
        """Return the raster's bounds in latitude and longitude, for error messages."""
        w, s, e, n = self._warp.transform_bounds(self.ds.crs, 'EPSG:4326', *self.ds.bounds)
        return f'lat {s:.6f}..{n:.6f}, lon {w:.6f}..{e:.6f}'


def _missing_side(inside: NDArray) -> tuple[str, tuple[int, int]] | None:
    """Find the side of the grid (rows along north) most outside the DEM.

    Returns the side and its first point outside (row, column), or None if covered.

    A box poking out to the north leaves its whole north edge and the north ends of its
    west and east edges uncovered: the side named is the one with the largest share out.
    """
    if inside.all():
        return None
    ny, nx = inside.shape
    edges = {'west': (np.arange(ny), np.zeros(ny, int)),
             'east': (np.arange(ny), np.full(ny, nx - 1)),
             'south': (np.zeros(nx, int), np.arange(nx)),
             'north': (np.full(nx, ny - 1), np.arange(nx))}
    share = {side: float(np.mean(~inside[idx])) for side, idx in edges.items()}
    side = max(share, key=share.get)
    if share[side] == 0:
        k = np.unravel_index(int(np.argmax(~inside)), inside.shape)
        return 'interior', (int(k[0]), int(k[1]))
    rows, cols = edges[side]
    i = int(np.argmax(~inside[rows, cols]))
    return side, (int(rows[i]), int(cols[i]))


def dem_grid(path: str | Path, datum: Datum, box: Box, resolution: float | None = None,
             height_offset: float = 0.0, name: str | None = None
             ) -> tuple[NDArray, float, NDArray]:
    """Resample a GeoTIFF DEM onto the ENU grid of a box.

    Args:
        path: The GeoTIFF.
        datum: Origin of the ENU frame.
        box: Flight box [m]; the grid covers its x-y extent.
        resolution: Grid spacing [m]; None for the DEM's own (see the module docstring).
        height_offset: Added to every DEM height [m] (the geoid undulation of a DEM
            above the geoid).
        name: The file as the scenario names it, for errors (default: `path`).

    Returns:
        ``(origin (2,) [m], resolution [m], heights (ny, nx) [m])`` in the ENU frame, as
        :meth:`~threat_planner.core.world.terrain.Terrain.from_arrays` takes them.

    Raises:
        InputError: naming ``terrain.dem`` and what is wrong: an unreadable file, heights
            not in metres, a box side the DEM does not cover, missing data.
    """
    import rasterio
    name = str(path) if name is None else name
    try:
        ds = rasterio.open(path)
    except (rasterio.errors.RasterioIOError, OSError) as exc:
        raise InputError(f'terrain.dem: cannot read {name} as a raster ({exc})') from None
    with ds:
        dem = _Dem(ds, name)
        width = box.hi[:2] - box.lo[:2]
        centre = datum.to_geodetic(np.array([*(0.5 * (box.lo[:2] + box.hi[:2])), 0.0]))
        if resolution is None:
            resolution = dem.spacing_m(datum, float(centre[0]), float(centre[1]))
        res = max(float(resolution), float(width.max()) / (MAX_GRID_POINTS - 1))
        n = np.ceil(width / res - 1e-9).astype(int) + 1
        x = np.minimum(box.lo[0] + res * np.arange(n[0]), box.hi[0])
        y = np.minimum(box.lo[1] + res * np.arange(n[1]), box.hi[1])
        gx, gy = np.meshgrid(x, y)
        z = np.zeros_like(gx)
        for _ in range(HEIGHT_STEPS):
            geo = datum.to_geodetic(np.stack([gx, gy, z], axis=-1))
            lat, lon, h = geo[..., 0], geo[..., 1], geo[..., 2]
            col, row = dem.pixels(lat, lon)
            inside = dem.covers(col, row)
            missing = _missing_side(inside)
            if missing is not None:
                side, k = missing
                edge = {'west': f'x = {box.lo[0]:g} m', 'east': f'x = {box.hi[0]:g} m',
                        'south': f'y = {box.lo[1]:g} m', 'north': f'y = {box.hi[1]:g} m',
                        'interior': 'inside'}[side]
                raise InputError(
                    f'terrain.dem: {name} does not cover the box\'s {side} side ({edge}; '
                    f'first uncovered point lat {lat[k]:.6f}, lon {lon[k]:.6f}); the DEM '
                    f'spans {dem.extent()}')
            step = dem.sample(col, row, lat, lon) + height_offset - h
            z = z + step
            if np.abs(step).max() < HEIGHT_TOLERANCE_M:
                break
        return np.array(box.lo[:2], float), res, z
