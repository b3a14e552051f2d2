"""
Conversions between ROS 2 messages and the numpy arrays of the planning core.

The planning core never imports rclpy or message packages; the node calls these
functions at its edge.  Every reader validates what it decodes and raises
:class:`threat_planner.errors.InputError` with a one-line message naming the bad
field and value, so that a bad message is refused before it reaches the planner.

Conventions: positions are in metres [m] in the message's frame, angles follow
REP-103 (x forward, y left, z up; a positive pitch about y points the nose down).

One module per message family: :mod:`._common` (stamps, headers, shared checks),
:mod:`.cloud` (PointCloud2), :mod:`.poses` (PoseArray, PoseStamped), :mod:`.paths` (Path),
:mod:`.markers` (MarkerArray), :mod:`.diagnostics` (DiagnosticArray), :mod:`.airspace`
(no-fly zones as MarkerArray, terrain as Image), :mod:`.fix` (NavSatFix), :mod:`.odom`
(Odometry: the vehicle's position and heading).
"""

from threat_planner.ros.conversions._common import ns_to_stamp, stamp_to_ns
from threat_planner.ros.conversions.airspace import (image_from_terrain, terrain_from_image,
                                                     zones_from_markers, zones_to_markers)
from threat_planner.ros.conversions.cloud import (moving_threats_from_pointcloud2,
                                                  pointcloud2_from_threats,
                                                  threats_from_pointcloud2)
from threat_planner.ros.conversions.diagnostics import (PLAN_STATUS_NAME, plan_info_msg,
                                                        plan_info_values)
from threat_planner.ros.conversions.fix import navsatfix_from_geodetic, point_from_navsatfix
from threat_planner.ros.conversions.markers import network_markers, SPHERES_PER_THREAT_MAX
from threat_planner.ros.conversions.odom import Vehicle, vehicle_from_odometry
from threat_planner.ros.conversions.paths import path_from_msg, path_to_msg
from threat_planner.ros.conversions.poses import point_from_pose_stamped, threats_from_pose_array

__all__ = [
    'PLAN_STATUS_NAME',
    'SPHERES_PER_THREAT_MAX',
    'Vehicle',
    'image_from_terrain',
    'moving_threats_from_pointcloud2',
    'navsatfix_from_geodetic',
    'network_markers',
    'ns_to_stamp',
    'path_from_msg',
    'path_to_msg',
    'plan_info_msg',
    'plan_info_values',
    'point_from_navsatfix',
    'point_from_pose_stamped',
    'pointcloud2_from_threats',
    'stamp_to_ns',
    'terrain_from_image',
    'threats_from_pointcloud2',
    'threats_from_pose_array',
    'vehicle_from_odometry',
    'zones_from_markers',
    'zones_to_markers',
]
