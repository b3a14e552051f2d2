"""One sample recording for the bag tests: what test_recording*.py write and check.

write_sample records one latched Path, two PointClouds and one DiagnosticArray at the
times T0...; check_sample checks what a reader gives back, field by field.
"""

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

from threat_planner.bag import LATCHED_QOS, McapRecorder

SEPARATOR = '=' * 80
T0 = 1_700_000_000_123_456_789  # ns; odd digits catch any float rounding of times


def make_path(n=4):
    msg = PathMsg()
    msg.header.frame_id = 'map'
    msg.header.stamp = Time(sec=1_700_000_000, nanosec=42)
    for i in range(n):
        pose = PoseStamped()
        pose.header.frame_id = 'map'
        pose.pose.position.x = 1.5 * i
        pose.pose.position.y = -2.0 * i
        pose.pose.position.z = 10.0 + i
        msg.poses.append(pose)
    return msg


def make_cloud():
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    msg = PointCloud2()
    msg.header.frame_id = 'world'
    msg.header.stamp = Time(sec=5, nanosec=6)
    msg.height, msg.width = 1, 4
    msg.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                  for k, n in enumerate('xyz')]
    msg.point_step, msg.row_step = 12, 48
    msg.data = points.tobytes()
    msg.is_dense = True
    return msg


def make_diagnostics():
    msg = DiagnosticArray()
    msg.header.stamp = Time(sec=7, nanosec=8)
    msg.status = [DiagnosticStatus(level=DiagnosticStatus.WARN, name='planner',
                                   message='slow', hardware_id='cpu0',
                                   values=[KeyValue(key='plan_ms', value='12.5')])]
    return msg


def write_sample(target, **kwargs):
    """Record one Path (latched), two clouds and one DiagnosticArray; return the recorder."""
    with McapRecorder(target, **kwargs) as rec:
        rec.add_topic('/planned_path', 'nav_msgs/msg/Path', LATCHED_QOS)
        rec.write('/planned_path', make_path(), log_time_ns=T0, publish_time_ns=T0 - 7)
        rec.write('/threats', make_cloud(), log_time_ns=T0 + 1)
        rec.write('/threats', make_cloud(), log_time_ns=T0 + 1_000_000_003,
                  publish_time_ns=T0 + 999)
        rec.write('/diagnostics', make_diagnostics(), log_time_ns=T0 + 2_000_000_000)
    return rec


def check_path(msg, n=4):
    assert msg.header.frame_id == 'map'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 42)
    assert len(msg.poses) == n
    for i, pose in enumerate(msg.poses):
        p = pose.pose.position
        assert (p.x, p.y, p.z) == (1.5 * i, -2.0 * i, 10.0 + i)
        assert pose.pose.orientation.w == 1.0


def check_cloud(msg):
    assert msg.header.frame_id == 'world'
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 4, 12, 48)
    assert [f.name for f in msg.fields] == ['x', 'y', 'z']
    assert [f.offset for f in msg.fields] == [0, 4, 8]
    assert all(f.datatype == PointField.FLOAT32 for f in msg.fields)
    points = np.frombuffer(bytes(msg.data), dtype=np.float32).reshape(4, 3)
    np.testing.assert_array_equal(points, np.arange(12, dtype=np.float32).reshape(4, 3))
    assert msg.is_dense


def check_diagnostics(msg):
    (status,) = msg.status
    assert (status.name, status.message, status.hardware_id) == ('planner', 'slow', 'cpu0')
    # 'byte' decodes as int (mcap_ros2, rosbags) or as a 1-byte bytes object (rclpy).
    level = status.level if isinstance(status.level, int) else status.level[0]
    assert level == 1
    assert [(kv.key, kv.value) for kv in status.values] == [('plan_ms', '12.5')]


EXPECTED_TIMES = [
    ('/planned_path', 'nav_msgs/msg/Path', T0, T0 - 7),
    ('/threats', 'sensor_msgs/msg/PointCloud2', T0 + 1, T0 + 1),
    ('/threats', 'sensor_msgs/msg/PointCloud2', T0 + 1_000_000_003, T0 + 999),
    ('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', T0 + 2_000_000_000,
     T0 + 2_000_000_000),
]


def check_sample(messages):
    assert [m[:4] for m in messages] == EXPECTED_TIMES
    check_path(messages[0].msg)
    check_cloud(messages[1].msg)
    check_cloud(messages[2].msg)
    check_diagnostics(messages[3].msg)
