"""Delaunay partition, incentre network, Dijkstra, surface seeds (imports: cost, world)."""
