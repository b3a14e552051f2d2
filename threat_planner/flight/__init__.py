"""Simulated flights: events files, the point-mass vehicle, the fly loop (ROS-free)."""
