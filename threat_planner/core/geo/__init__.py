"""WGS84 datum, geodetic <-> local ENU conversions, DEM terrain (imports: world, errors)."""
