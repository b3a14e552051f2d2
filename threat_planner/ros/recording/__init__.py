"""Bag tools that run the ROS edge: record a plan as the node would, replay, feed a node live."""
