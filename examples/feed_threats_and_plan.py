#!/usr/bin/env python3
"""Feed a threat picture to a running planner_node and ask it for a plan with GetPlan.

Only rclpy and standard messages: a node of your own does the same. Run a planner first
(``planner_node``), then::

    python examples/feed_threats_and_plan.py [--namespace /uav1] [--threats 20]

The picture is a PointCloud2 with float32 fields x, y, z [m] and intensity F [m^4], on
``threats`` with reliable, transient-local QoS (the node keeps the latest picture and a
late-joining node still gets it). The request's start and goal are PoseStamped in the
node's ``frame_id`` (``map`` by default) inside its ``bounds``; an empty path in the answer
means refused, and the node logs why. Exit status 0 with a path, 1 without.
"""

import argparse
import sys

from geometry_msgs.msg import PoseStamped
from nav_msgs.srv import GetPlan
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2, PointField

# The QoS the planner subscribes to its threat picture with.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def threat_cloud(positions, intensities, frame_id, stamp):
    """Pack (N, 3) positions [m] and (N,) intensities into a dense PointCloud2."""
    points = np.zeros(len(positions), dtype=[(f, '<f4') for f in ('x', 'y', 'z', 'intensity')])
    points['x'], points['y'], points['z'] = np.asarray(positions, dtype=float).T
    points['intensity'] = intensities
    msg = PointCloud2(height=1, width=len(points), is_bigendian=False, point_step=16,
                      row_step=16 * len(points), is_dense=True, data=points.tobytes())
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, name in enumerate(('x', 'y', 'z', 'intensity'))]
    return msg


def pose(xyz, frame_id, stamp):
    """A PoseStamped at `xyz` [m]."""
    msg = PoseStamped()
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, xyz)
    msg.pose.orientation.w = 1.0
    return msg


def main(argv=None):
    """Publish random threats in a 100 m box, request a corner-to-corner plan, print it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--namespace', default='', help='the planner\'s namespace, e.g. /uav1')
    parser.add_argument('--threats', type=int, default=20, help='how many random threats')
    parser.add_argument('--frame-id', default='map')
    parser.add_argument('--timeout', type=float, default=30.0, help='[s]')
    args, ros_args = parser.parse_known_args(argv)

    rclpy.init(args=[sys.argv[0]] + ros_args)   # Jazzy's init is not a context manager
    node = Node('feed_threats_and_plan', namespace=args.namespace or None)
    try:
        with SingleThreadedExecutor() as executor:
            executor.add_node(node)
            stamp = node.get_clock().now().to_msg()
            rng = np.random.default_rng(1)
            positions = rng.uniform([10, 10, 10], [90, 90, 90], size=(args.threats, 3))
            # F = 1.6e5 weighs like one metre of length per metre at F^(1/4) = 20 m.
            intensities = rng.uniform(0.5e5, 2.5e5, size=args.threats)
            pub = node.create_publisher(PointCloud2, 'threats', LATCHED)
            pub.publish(threat_cloud(positions, intensities, args.frame_id, stamp))

            client = node.create_client(GetPlan, 'plan_path')
            if not client.wait_for_service(timeout_sec=args.timeout):
                print(f'no {client.srv_name} service within {args.timeout:g} s',
                      file=sys.stderr)
                return 1
            request = GetPlan.Request(start=pose([0, 0, 50], args.frame_id, stamp),
                                      goal=pose([100, 100, 50], args.frame_id, stamp))
            # The picture is latched, but the node may take it a moment after matching:
            # ask again until the answer is a path (a refusal is logged by the node).
            deadline = node.get_clock().now().nanoseconds + int(args.timeout * 1e9)
            while node.get_clock().now().nanoseconds < deadline:
                future = client.call_async(request)
                executor.spin_until_future_complete(future, timeout_sec=args.timeout)
                path = future.result().plan if future.done() else None
                if path is not None and path.poses:
                    first, last = path.poses[0].pose.position, path.poses[-1].pose.position
                    print(f'{len(path.poses)} poses in {path.header.frame_id} from '
                          f'({first.x:.1f}, {first.y:.1f}, {first.z:.1f}) to '
                          f'({last.x:.1f}, {last.y:.1f}, {last.z:.1f})')
                    return 0
                executor.spin_once(timeout_sec=0.5)
            print('no path: see the planner\'s log for the reason', file=sys.stderr)
            return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
