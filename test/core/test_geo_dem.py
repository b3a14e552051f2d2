"""DEM terrain: a GeoTIFF written here in UTM gives the terrain the same heights give as an
array, computed independently (PROJ for every conversion, bisection for the ground)."""

import numpy as np
from pyproj import Transformer
import pytest
import rasterio
from rasterio.transform import from_origin
import yaml

from threat_planner.core.inputs.scenario import load_scenario, scenario_from_dict
from threat_planner.errors import ScenarioError

DATUM = [47.0, 8.0, 450.0]
UTM = 'EPSG:32632'
PIXEL = 30.0
TO_UTM = Transformer.from_crs('EPSG:4326', UTM, always_xy=True)
E0, N0 = TO_UTM.transform(DATUM[1], DATUM[0])


def plane(e, n):
    """DEM heights [m]: a tilted plane (bilinear reading reproduces it exactly)."""
    return 520.0 + 0.08 * (e - E0) - 0.05 * (n - N0)


def write_dem(path, nodata_at=None, unit=None, west=-2000.0, size=(160, 200)):
    ny, nx = size
    x0, y0 = E0 + west, N0 + 3000.0
    cols, rows = np.meshgrid(np.arange(nx) + 0.5, np.arange(ny) + 0.5)
    heights = plane(x0 + cols * PIXEL, y0 - rows * PIXEL).astype('float32')
    if nodata_at is not None:
        heights[nodata_at] = -9999.0
    with rasterio.open(path, 'w', driver='GTiff', width=nx, height=ny, count=1,
                       dtype='float32', crs=UTM, transform=from_origin(x0, y0, PIXEL, PIXEL),
                       nodata=-9999.0) as ds:
        ds.write(heights, 1)
        if unit:
            ds.set_band_unit(1, unit)
    return path


def scenario(dem, resolution=100.0, **terrain):
    return {'name': 'dem', 'datum': DATUM, 'coordinates': 'geodetic',
            'bounds': {'min': [47.0, 8.0, 450.0], 'max': [47.018, 8.04, 1100.0]},
            'start': [47.001, 8.001, 700.0], 'goal': [47.017, 8.039, 700.0], 'threats': [],
            'terrain': {'dem': str(dem), 'clearance': 10.0,
                        **({} if resolution is None else {'resolution': resolution}),
                        **terrain}}


def expected_heights(xs, ys):
    """ENU z of the ground under each (x, y): bisection on PROJ's ENU -> geodetic."""
    lat0, lon0, h0 = DATUM
    to_geo = Transformer.from_pipeline(
        f'+proj=pipeline +step +inv +proj=topocentric +ellps=WGS84 +lat_0={lat0} '
        f'+lon_0={lon0} +h_0={h0} +step +inv +proj=cart +ellps=WGS84 +step '
        '+proj=unitconvert +xy_in=rad +xy_out=deg')
    gx, gy = np.meshgrid(xs, ys)
    lo, hi = np.full(gx.shape, -1000.0), np.full(gx.shape, 2000.0)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lon, lat, h = to_geo.transform(gx, gy, mid)
        e, n = TO_UTM.transform(lon, lat)
        above = h > plane(e, n)
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    return 0.5 * (lo + hi)


def test_dem_terrain_equals_the_same_heights_as_an_array(tmp_path):
    s = scenario_from_dict(scenario(write_dem(tmp_path / 'dem.tif')), str(tmp_path / 's.yaml'))
    t = s.airspace.terrain
    box = s.box
    assert t.resolution == 100.0 and np.array_equal(t.origin, box.lo[:2])
    xs = np.minimum(box.lo[0] + 100.0 * np.arange(t.heights.shape[1]), box.hi[0])
    ys = np.minimum(box.lo[1] + 100.0 * np.arange(t.heights.shape[0]), box.hi[1])
    assert xs[-1] == box.hi[0] and ys[-1] == box.hi[1]
    expected = expected_heights(xs, ys)
    assert np.abs(t.heights - expected).max() < 1e-3
    # The same heights as an array, in a local scenario: the same terrain floor.
    local = s.to_dict()
    local['terrain']['heights'] = expected.tolist()
    twin = scenario_from_dict(local)
    a = np.array([[100.0, 100.0, 150.0], [2500.0, 300.0, 120.0], [800.0, 1900.0, 90.0]])
    b = np.array([[2900.0, 1800.0, 160.0], [300.0, 1500.0, 100.0], [2000.0, 100.0, 200.0]])
    np.testing.assert_allclose(t.clearance_margin(a, b),
                               twin.airspace.terrain.clearance_margin(a, b), atol=1e-3)
    assert t.clearance == twin.airspace.terrain.clearance == 10.0


def test_the_comparison_can_fail_by_half_a_pixel(tmp_path):
    """A DEM read half a pixel off (its corner taken for its centre) misses by > 1 mm."""
    s = scenario_from_dict(scenario(write_dem(tmp_path / 'dem.tif')))
    t = s.airspace.terrain
    xs = np.minimum(s.box.lo[0] + 100.0 * np.arange(t.heights.shape[1]), s.box.hi[0])
    ys = np.minimum(s.box.lo[1] + 100.0 * np.arange(t.heights.shape[0]), s.box.hi[1])
    shifted = expected_heights(xs + PIXEL / 2, ys)
    assert np.abs(t.heights - shifted).max() > 0.5


def test_default_resolution_is_the_dem_spacing_in_enu(tmp_path):
    s = scenario_from_dict(scenario(write_dem(tmp_path / 'dem.tif'), resolution=None))
    assert abs(s.airspace.terrain.resolution - PIXEL) < 0.05


def test_a_dem_not_covering_the_box_names_the_missing_side(tmp_path):
    dem = write_dem(tmp_path / 'dem.tif', west=200.0)
    with pytest.raises(ScenarioError, match=r"does not cover the box's west side \(x = 0 m"):
        scenario_from_dict(scenario(dem))
    dem = write_dem(tmp_path / 'small.tif', size=(160, 160))
    with pytest.raises(ScenarioError, match="does not cover the box's east side"):
        scenario_from_dict(scenario(dem))


def test_nodata_feet_and_no_datum_are_refused(tmp_path):
    dem = write_dem(tmp_path / 'holes.tif', nodata_at=(60, 80))
    with pytest.raises(ScenarioError, match=r'terrain.dem: .*holes.tif has no data .*next to'):
        scenario_from_dict(scenario(dem, resolution=30.0))
    feet = write_dem(tmp_path / 'feet.tif', unit='ft')
    with pytest.raises(ScenarioError, match="heights in 'ft'; metres needed"):
        scenario_from_dict(scenario(feet))
    doc = scenario(write_dem(tmp_path / 'dem.tif'))
    doc.pop('datum')
    doc['coordinates'] = 'local'
    doc['bounds'] = {'min': [0, 0, 0], 'max': [100, 100, 100]}
    doc['start'], doc['goal'] = [1, 1, 50], [99, 99, 50]
    with pytest.raises(ScenarioError, match='terrain.dem: a DEM needs the scenario'):
        scenario_from_dict(doc)
    with pytest.raises(ScenarioError, match=r'terrain.origin: not a key of a DEM terrain'):
        scenario_from_dict({**scenario(tmp_path / 'dem.tif'),
                            'terrain': {'dem': 'dem.tif', 'origin': [0, 0]}})
    with pytest.raises(ScenarioError, match='terrain.dem: cannot read nowhere.tif'):
        scenario_from_dict(scenario('nowhere.tif'), str(tmp_path / 's.yaml'))


def test_height_offset_shifts_the_floor_and_the_file_is_relative_to_the_scenario(tmp_path):
    write_dem(tmp_path / 'dem.tif')
    (tmp_path / 'a.yaml').write_text(yaml.safe_dump(scenario('dem.tif')))
    (tmp_path / 'b.yaml').write_text(yaml.safe_dump(scenario('dem.tif', height_offset=-48.5)))
    a, b = (load_scenario(tmp_path / n).airspace.terrain for n in ('a.yaml', 'b.yaml'))
    # 48.5 m lower above the ellipsoid is 48.5 m lower in ENU, to the lean of the ENU
    # vertical (0.03 deg here) times the slope: 48.5 * 5e-4 * 0.09 = 2 mm
    np.testing.assert_allclose(b.heights - a.heights, -48.5, atol=3e-3)
