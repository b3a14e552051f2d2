"""Write the example's DEM, valley_dem.tif: a synthetic valley in UTM zone 32N (EPSG:32632).

30 m pixels, heights in metres above the WGS84 ellipsoid: a valley floor at ~430 m rising
to the west and east, with a ridge across it and two hills. Run from anywhere:

    .venv/bin/python examples/geo/make_dem.py
"""

from pathlib import Path

import numpy as np
from pyproj import Transformer
import rasterio
from rasterio.transform import from_origin

HERE = Path(__file__).resolve().parent
PIXEL = 30.0
#: South-west and north-east corners of the DEM [deg] (the scenario's box lies inside).
SOUTH_WEST, NORTH_EAST = (47.3660, 8.5240), (47.3920, 8.5660)


def heights(e: np.ndarray, n: np.ndarray, e0: float, n0: float) -> np.ndarray:
    """Terrain height [m] at UTM easting, northing [m] (e0, n0: the DEM's centre)."""
    x, y = (e - e0) / 1000.0, (n - n0) / 1000.0
    valley = 430.0 + 45.0 * x ** 2
    ridge = 110.0 * np.exp(-((y + 0.35 * x) / 0.25) ** 2) * np.exp(-(x / 0.9) ** 2)
    hills = (90.0 * np.exp(-((x + 0.8) ** 2 + (y - 0.6) ** 2) / 0.12)
             + 70.0 * np.exp(-((x - 0.9) ** 2 + (y + 0.5) ** 2) / 0.10))
    return valley + ridge + hills


def main() -> Path:
    """Write the GeoTIFF; return its path."""
    utm = Transformer.from_crs('EPSG:4326', 'EPSG:32632', always_xy=True)
    w, s = utm.transform(SOUTH_WEST[1], SOUTH_WEST[0])
    e, n = utm.transform(NORTH_EAST[1], NORTH_EAST[0])
    w, s, e, n = (np.floor(w / PIXEL) * PIXEL, np.floor(s / PIXEL) * PIXEL,
                  np.ceil(e / PIXEL) * PIXEL, np.ceil(n / PIXEL) * PIXEL)
    nx, ny = int((e - w) / PIXEL), int((n - s) / PIXEL)
    cols, rows = np.meshgrid(np.arange(nx) + 0.5, np.arange(ny) + 0.5)
    z = heights(w + cols * PIXEL, n - rows * PIXEL, 0.5 * (w + e), 0.5 * (s + n))
    path = HERE / 'valley_dem.tif'
    with rasterio.open(path, 'w', driver='GTiff', width=nx, height=ny, count=1,
                       dtype='float32', crs='EPSG:32632', nodata=-9999.0,
                       transform=from_origin(w, n, PIXEL, PIXEL), compress='deflate') as ds:
        ds.write(z.astype('float32'), 1)
        ds.set_band_unit(1, 'metre')
    return path


if __name__ == '__main__':
    print(main())
