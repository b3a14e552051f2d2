"""Plans out to autopilots and maps: QGC plan, QGC WPL 110, GeoJSON, thinning (imports: core)."""
