"""WGS84 <-> ENU: round trips to 1 mm, PROJ's own pipeline agrees to 1 cm, bad input named."""

from hypothesis import given, settings, strategies as st
import numpy as np
from pyproj import Transformer
import pytest

from threat_planner.core.geo.frames import (check_latlon, Datum, enu_box, flattening_m,
                                            MAX_SPAN_M)
from threat_planner.errors import InputError

HALF = 50_000.0   # a 100 km box around the datum


def proj_enu(datum):
    """PROJ's geodetic -> ECEF -> topocentric pipeline (independent of pymap3d)."""
    return Transformer.from_pipeline(
        f'+proj=pipeline +step +proj=axisswap +order=2,1 +step +proj=unitconvert '
        f'+xy_in=deg +xy_out=rad +step +proj=cart +ellps=WGS84 +step +proj=topocentric '
        f'+ellps=WGS84 +lat_0={datum.lat_deg!r} +lon_0={datum.lon_deg!r} +h_0={datum.h_m!r}')


datums = st.builds(Datum, st.floats(-85.0, 85.0), st.floats(-180.0, 180.0),
                   st.floats(-400.0, 5000.0))


@settings(max_examples=60, deadline=None)
@given(datums, st.integers(0, 2**32 - 1))
def test_round_trip_1_mm_and_proj_agrees_1_cm_over_100_km(datum, seed):
    rng = np.random.default_rng(seed)
    enu = np.column_stack([rng.uniform(-HALF, HALF, (200, 2)), rng.uniform(-500, 9000, 200)])
    geo = datum.to_geodetic(enu)
    assert np.abs(geo[:, 0]).max() <= 90 and np.abs(geo[:, 1]).max() <= 180
    assert np.abs(datum.to_enu(geo) - enu).max() < 1e-3
    e, n, u = proj_enu(datum).transform(geo[:, 0], geo[:, 1], geo[:, 2])
    assert np.abs(np.column_stack([e, n, u]) - enu).max() < 1e-2


def test_the_proj_cross_check_can_fail():
    """A datum 1e-7 deg off (1.1 cm north) is seen by the 1 cm comparison."""
    d = Datum(47.0, 8.0, 400.0)
    geo = d.to_geodetic(np.array([[1000.0, 2000.0, 30.0]]))
    e, n, u = proj_enu(Datum(47.0 + 1e-7, 8.0, 400.0)).transform(geo[:, 0], geo[:, 1],
                                                                 geo[:, 2])
    assert abs(n[0] - 2000.0) > 1e-2


def test_box_is_spanned_by_its_two_corners():
    d = Datum(46.0, 7.0, 500.0)
    box = enu_box(d, [46.0, 7.0, 500.0], [46.1, 7.2, 1500.0])
    lo, hi = d.to_enu([[46.0, 7.0, 500.0], [46.1, 7.2, 1500.0]])
    np.testing.assert_array_equal(box.lo, lo)
    np.testing.assert_array_equal(box.hi, hi)
    assert 15_000 < box.hi[0] < 16_000 and 11_000 < box.hi[1] < 11_200


@pytest.mark.parametrize('lo, hi, message', [
    ([91.0, 7.0, 0.0], [46.1, 7.2, 900.0], 'bounds.min: latitude 91 outside [-90, 90]'),
    ([46.0, 7.0, 0.0], [46.1, 181.5, 900.0], 'bounds.max: longitude 181.5 outside '
                                             '[-180, 180]'),
    ([46.1, 7.0, 0.0], [46.0, 7.2, 900.0], 'bounds.max: latitude 46 (north) must exceed'),
    ([46.0, 7.0, 900.0], [46.1, 7.2, 900.0], 'bounds.max: height 900 (ceiling) must exceed'),
    ([46.0, 7.2, 0.0], [46.1, 7.0, 900.0], "bounds.max: its east coordinate"),
    ([46.0, 7.0, 0.0], [46.1, 7.0, 'x'], 'bounds.max: expected [lat, lon, h]'),
])
def test_bad_corners_are_named(lo, hi, message):
    with pytest.raises(InputError) as exc:
        enu_box(Datum(46.0, 7.0, 0.0), lo, hi)
    assert message in str(exc.value)
    assert '\n' not in str(exc.value)


def test_a_box_wider_than_200_km_is_refused_with_the_flattening_it_would_cost():
    d = Datum(45.0, 8.0, 0.0)
    ok = enu_box(d, [45.0, 8.0, 0.0], [45.5, 10.5, 5000.0])
    assert 190e3 < ok.hi[0] < MAX_SPAN_M
    with pytest.raises(InputError) as exc:
        enu_box(d, [45.0, 8.0, 0.0], [45.5, 10.6, 5000.0])
    east = d.to_enu([45.5, 10.6, 5000.0])[0]
    assert east > MAX_SPAN_M
    text = str(exc.value)
    assert text.startswith(f'bounds: the box spans {east / 1e3:.1f} km east-west')
    # the heights quoted are pymap3d's: the ENU level plane 200 km out, above the ellipsoid
    assert f'{flattening_m(d, MAX_SPAN_M):.0f} m at 200 km' in text
    assert 3100 < flattening_m(d, MAX_SPAN_M) < 3160   # ~ d^2 / 2R, R ~ 6.37e6 m
    # The datum counts: a small box 150 km from it spans more than 200 km with it.
    with pytest.raises(InputError, match='north-south'):
        enu_box(d, [46.8, 8.0, 0.0], [46.9, 8.1, 3000.0])


def test_latitude_longitude_checks_name_the_row():
    with pytest.raises(InputError, match=r'^threats\[2\]: longitude -190 outside'):
        check_latlon('threats', [1, 2, 3], [4, 5, -190], rows=True)
    with pytest.raises(InputError, match='^datum: latitude nan outside'):
        check_latlon('datum', np.nan, 0)
    with pytest.raises(InputError, match='pole'):
        Datum.parse([90.0, 0.0, 0.0])
