"""Threats, flight box, no-fly zones, terrain: what the UAV flies through (imports: errors)."""
