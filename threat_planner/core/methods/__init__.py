"""paper, improved, best on one problem; basins, warm starts, airspace (imports: all below)."""
