"""Threat-aware 3-D UAV path planning after Qu, Zhang and Zhang (Delaunay incentre network)."""
