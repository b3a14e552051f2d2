"""The node's interface: its name, topics, message types and QoS, declared once.

A threat message is the whole threat picture (it replaces the previous one), so the threat
inputs (and the airspace inputs ``no_fly_zones`` and ``terrain``, also whole) subscribe
transient local like a map: a node started after a latched publisher still
gets the current picture, and a volatile threat publisher is reported by rclpy as
incompatible QoS. Start and goal subscribe volatile so that RViz's pose tools (volatile
publishers) work. The GNSS fixes ``start_fix`` and ``goal_fix`` subscribe best effort:
GNSS drivers publish sensor data best effort, which a reliable subscription would not
match, and a best-effort one takes reliable publishers too; the vehicle's ``odom`` (issue
44) is sensor data streamed at tens of hertz and subscribes alike. Outputs are latched
(RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 1).
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from threat_planner.bag.qos import TopicQos

__all__ = ['FIX_INPUT', 'INPUT_TOPICS', 'LATCHED', 'NODE_NAME', 'OUTPUT_TOPICS',
           'PARAMETER_EVENTS_QOS', 'PARAMETER_EVENTS_TOPIC', 'PARAMETER_EVENT_TYPE',
           'POSE_INPUT', 'THREAT_INPUT']

NODE_NAME = 'threat_planner'

#: Outputs: late subscribers (RViz, a recorder) get the last plan.
LATCHED = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=1)
#: Threat pictures: state, like a map.
THREAT_INPUT = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          history=HistoryPolicy.KEEP_LAST, depth=10)
#: Start and goal: volatile, as RViz's pose tools publish.
POSE_INPUT = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE,
                        history=HistoryPolicy.KEEP_LAST, depth=10)
#: GNSS fixes and odometry: best effort, as sensor drivers publish.
FIX_INPUT = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE,
                       history=HistoryPolicy.KEEP_LAST, depth=10)
#: rclpy's parameter events QoS, for the recording's channel metadata.
PARAMETER_EVENTS_QOS = TopicQos(reliability='reliable', durability='volatile',
                                history='keep_last', depth=1000)
PARAMETER_EVENTS_TOPIC = '/parameter_events'
PARAMETER_EVENT_TYPE = 'rcl_interfaces/msg/ParameterEvent'

#: The node's inputs: topic name (relative) -> (type, subscription QoS).
INPUT_TOPICS = {
    'threats': ('sensor_msgs/msg/PointCloud2', THREAT_INPUT),
    'threat_poses': ('geometry_msgs/msg/PoseArray', THREAT_INPUT),
    'start': ('geometry_msgs/msg/PoseStamped', POSE_INPUT),
    'goal_pose': ('geometry_msgs/msg/PoseStamped', POSE_INPUT),
    # airspace (issue 12): latched state like the threat picture (ros/conversions/airspace.py)
    'no_fly_zones': ('visualization_msgs/msg/MarkerArray', THREAT_INPUT),
    'terrain': ('sensor_msgs/msg/Image', THREAT_INPUT),
    # geo (issue 26): sensor_msgs/NavSatFix, converted into frame_id with parameter datum
    'start_fix': ('sensor_msgs/msg/NavSatFix', FIX_INPUT),
    'goal_fix': ('sensor_msgs/msg/NavSatFix', FIX_INPUT),
    # flight (issue 44): the vehicle's position and velocity, a stream (ros/flight.py)
    'odom': ('nav_msgs/msg/Odometry', FIX_INPUT),
}
#: The node's outputs: topic name (relative) -> (type, publisher QoS).
OUTPUT_TOPICS = {
    'initial_path': ('nav_msgs/msg/Path', LATCHED),
    'path': ('nav_msgs/msg/Path', LATCHED),
    'network': ('visualization_msgs/msg/MarkerArray', LATCHED),
    'plan_info': ('diagnostic_msgs/msg/DiagnosticArray', LATCHED),
}
