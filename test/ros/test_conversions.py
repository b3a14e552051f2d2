"""Tests of threat_planner.ros.conversions' inputs (clouds, poses) against real ROS 2 messages."""

import math
import time

from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

from conversion_samples import _threats, FRAME, STAMP
from threat_planner.errors import InputError
from threat_planner.ros import conversions as conv


def _cloud(positions, intensities, *, layout, big_endian=False, point_step=None,
           row_pad=0, height=1, frame=FRAME, extra_fields=()):
    """
    Build a PointCloud2 by hand with an arbitrary field layout.

    `layout` maps field name to (offset, datatype); `row_pad` bytes are appended to
    every row.  Unused bytes are filled with 0xAB so that a decoder reading padding
    would see garbage.
    """
    n = positions.shape[0]
    assert n % height == 0
    width = n // height
    order = '>' if big_endian else '<'
    fmt = {PointField.FLOAT32: 'f4', PointField.FLOAT64: 'f8'}
    needed = max(off + int(fmt[dt][1]) for off, dt in layout.values())
    point_step = needed if point_step is None else point_step
    row_step = width * point_step + row_pad
    buf = np.full(row_step * height, 0xAB, dtype=np.uint8)
    values = {'x': positions[:, 0], 'y': positions[:, 1], 'z': positions[:, 2],
              'intensity': intensities}
    for name, (off, dt) in layout.items():
        size = int(fmt[dt][1])
        encoded = values[name].astype(order + fmt[dt]).view(np.uint8).reshape(n, size)
        for p in range(n):
            row, col = divmod(p, width)
            start = row * row_step + col * point_step + off
            buf[start:start + size] = encoded[p]
    fields = [PointField(name=name, offset=off, datatype=dt, count=1)
              for name, (off, dt) in layout.items()]
    fields += list(extra_fields)
    msg = PointCloud2(header=Header(frame_id=frame, stamp=STAMP), height=height,
                      width=width, fields=fields, is_bigendian=big_endian,
                      point_step=point_step, row_step=row_step, is_dense=True)
    msg.data = buf.tobytes()
    return msg


F32, F64 = PointField.FLOAT32, PointField.FLOAT64
PACKED32 = {'x': (0, F32), 'y': (4, F32), 'z': (8, F32), 'intensity': (12, F32)}
PACKED64 = {'x': (0, F64), 'y': (8, F64), 'z': (16, F64), 'intensity': (24, F64)}
# Shuffled order, mixed sizes and a 4-byte hole between fields.
SHUFFLED = {'intensity': (0, F64), 'z': (12, F32), 'x': (16, F64), 'y': (24, F32)}


# ------------------------------------------------------------------ PointCloud2


def test_pointcloud2_from_threats_round_trip():
    positions, intensities = _threats()
    msg = conv.pointcloud2_from_threats(positions, intensities, FRAME, STAMP)
    assert isinstance(msg, PointCloud2)
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 7, 16, 112)
    assert [f.name for f in msg.fields] == ['x', 'y', 'z', 'intensity']
    assert all(f.datatype == PointField.FLOAT32 for f in msg.fields)
    assert not msg.is_bigendian and msg.is_dense
    assert msg.header.frame_id == FRAME and msg.header.stamp == STAMP
    pos, inten = conv.threats_from_pointcloud2(msg, FRAME)
    assert pos.dtype == np.float64 and pos.shape == (7, 3)
    assert inten.dtype == np.float64 and inten.shape == (7,)
    np.testing.assert_array_equal(pos, positions.astype(np.float32))
    np.testing.assert_array_equal(inten, intensities.astype(np.float32))


@pytest.mark.parametrize('layout', [PACKED32, PACKED64, SHUFFLED], ids=['f32', 'f64', 'mixed'])
@pytest.mark.parametrize('big_endian', [False, True], ids=['le', 'be'])
def test_pointcloud2_layouts_round_trip(layout, big_endian):
    positions, intensities = _threats(n=12)
    msg = _cloud(positions, intensities, layout=layout, big_endian=big_endian)
    pos, inten = conv.threats_from_pointcloud2(msg, FRAME)
    if all(dt == F64 for _, dt in layout.values()):
        np.testing.assert_array_equal(pos, positions)
        np.testing.assert_array_equal(inten, intensities)
    else:
        np.testing.assert_allclose(pos, positions, rtol=1e-6)
        np.testing.assert_allclose(inten, intensities, rtol=1e-6)
    if layout is SHUFFLED:
        # Fields stored as FLOAT64 come back bit-exact.
        np.testing.assert_array_equal(pos[:, 0], positions[:, 0])
        np.testing.assert_array_equal(inten, intensities)


def test_pointcloud2_point_step_row_padding_and_height():
    positions, intensities = _threats(n=12)
    extra = [PointField(name='rgb', offset=40, datatype=PointField.UINT32, count=1)]
    msg = _cloud(positions, intensities, layout=SHUFFLED, big_endian=True, point_step=48,
                 row_pad=20, height=3, extra_fields=extra)
    assert msg.row_step == 4 * 48 + 20
    pos, inten = conv.threats_from_pointcloud2(msg, FRAME)
    np.testing.assert_allclose(pos, positions, rtol=1e-6)
    np.testing.assert_array_equal(inten, intensities)


def test_pointcloud2_empty_cloud():
    msg = conv.pointcloud2_from_threats(np.empty((0, 3)), np.empty(0), FRAME, STAMP)
    pos, inten = conv.threats_from_pointcloud2(msg, FRAME)
    assert pos.shape == (0, 3) and inten.shape == (0,)


def _valid_cloud():
    positions, intensities = _threats(n=6)
    return _cloud(positions, intensities, layout=PACKED32)


def _reject(msg, *fragments, **kwargs):
    with pytest.raises(InputError) as info:
        conv.threats_from_pointcloud2(msg, FRAME, **kwargs)
    text = str(info.value)
    assert '\n' not in text
    for fragment in fragments:
        assert fragment in text, text
    return text


@pytest.mark.parametrize('name', ['x', 'y', 'z', 'intensity'])
def test_pointcloud2_rejects_missing_field(name):
    msg = _valid_cloud()
    msg.fields = [f for f in msg.fields if f.name != name]
    _reject(msg, 'missing', repr(name))


def test_pointcloud2_rejects_non_float_field():
    msg = _valid_cloud()
    msg.fields[3].datatype = PointField.UINT16
    _reject(msg, "'intensity'", 'UINT16', '(4)')


def test_pointcloud2_rejects_field_count():
    msg = _valid_cloud()
    msg.fields[1].count = 3
    _reject(msg, "'y'", 'count 3')


def test_pointcloud2_rejects_small_point_step():
    msg = _valid_cloud()
    msg.point_step = 12
    msg.row_step = 12 * msg.width
    _reject(msg, 'point_step 12', '16')


def test_pointcloud2_rejects_overlapping_fields():
    msg = _valid_cloud()
    msg.fields[1].offset = 2
    _reject(msg, 'overlap', "'x'", "'y'")


def test_pointcloud2_rejects_duplicate_field():
    msg = _valid_cloud()
    msg.fields = list(msg.fields) + [PointField(name='z', offset=0, datatype=F32, count=1)]
    _reject(msg, 'duplicate', "'z'")


def test_pointcloud2_rejects_truncated_data():
    msg = _valid_cloud()
    msg.data = bytes(msg.data)[:-5]
    _reject(msg, f'{len(msg.data)} bytes', str(msg.row_step * msg.height))


def test_pointcloud2_rejects_small_row_step():
    msg = _valid_cloud()
    msg.row_step = msg.width * msg.point_step - 1
    msg.data = bytes(msg.row_step)
    _reject(msg, f'row_step {msg.row_step}', str(msg.width * msg.point_step))


def test_pointcloud2_rejects_frame_mismatch():
    msg = _valid_cloud()
    msg.header.frame_id = 'odom'
    _reject(msg, "'odom'", "'map'")


@pytest.mark.parametrize('column, what', [(0, 'positions'), (2, 'positions'),
                                          (3, 'intensities')])
@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_pointcloud2_rejects_non_finite(column, what, bad):
    positions, intensities = _threats(n=9)
    table = np.column_stack([positions, intensities])
    table[[4, 7], column] = bad
    msg = _cloud(table[:, :3], table[:, 3], layout=PACKED64)
    _reject(msg, '2 non-finite', what, 'index 4')


@pytest.mark.parametrize('bad', [0.0, -3.5])
def test_pointcloud2_rejects_non_positive_intensity(bad):
    positions, intensities = _threats(n=9)
    intensities[[5, 6, 8]] = bad
    msg = conv.pointcloud2_from_threats(positions, intensities, FRAME, STAMP)
    _reject(msg, '3 non-positive', 'index 5', repr(bad))


def test_pointcloud2_rejects_too_many_points_before_decoding():
    n = 1_000_000
    msg = PointCloud2(header=Header(frame_id=FRAME), height=1, width=n,
                      fields=conv.pointcloud2_from_threats(
                          np.zeros((1, 3)), np.ones(1), FRAME, STAMP).fields,
                      point_step=16, row_step=16 * n)
    msg.data = bytes(16 * n)
    start = time.perf_counter()
    _reject(msg, '1000000', 'max_points=10000', max_points=10000)
    assert time.perf_counter() - start < 0.01
    # Garbage layout behind the count: the count check must come first.
    msg.data = b''
    msg.fields = []
    _reject(msg, 'max_points=10000', max_points=10000)
    # Exactly at the limit is fine.
    small = _valid_cloud()
    assert conv.threats_from_pointcloud2(small, FRAME, max_points=6)[0].shape == (6, 3)


# -------------------------------------------------------------------- poses


def _pose_array(points, frame=FRAME):
    return PoseArray(header=Header(frame_id=frame),
                     poses=[Pose(position=Point(x=x, y=y, z=z)) for x, y, z in points])


def test_pose_array_threats():
    points = [(1.0, 2.0, 3.0), (-4.5, 0.25, 9.0)]
    pos, inten = conv.threats_from_pose_array(_pose_array(points), FRAME, 2.5e4)
    np.testing.assert_array_equal(pos, np.array(points))
    np.testing.assert_array_equal(inten, [2.5e4, 2.5e4])
    pos, inten = conv.threats_from_pose_array(_pose_array([]), FRAME, 1.0)
    assert pos.shape == (0, 3) and inten.shape == (0,)


def test_pose_array_rejections():
    msg = _pose_array([(1.0, 2.0, 3.0), (0.0, math.nan, 0.0)])
    with pytest.raises(InputError, match=r'1 non-finite positions \(first at index 1'):
        conv.threats_from_pose_array(msg, FRAME, 1.0)
    good = _pose_array([(1.0, 2.0, 3.0)])
    with pytest.raises(InputError, match="'base_link'.*'map'"):
        conv.threats_from_pose_array(_pose_array([], frame='base_link'), FRAME, 1.0)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(InputError, match='default_intensity'):
            conv.threats_from_pose_array(good, FRAME, bad)
    with pytest.raises(InputError, match='2 points, more than max_points=1'):
        conv.threats_from_pose_array(_pose_array([(0, 0, 0), (1, 1, 1)]), FRAME, 1.0,
                                     max_points=1)


def test_point_from_pose_stamped():
    msg = PoseStamped(header=Header(frame_id=FRAME),
                      pose=Pose(position=Point(x=1.5, y=-2.0, z=30.0)))
    point = conv.point_from_pose_stamped(msg, FRAME)
    assert point.shape == (3,) and point.dtype == np.float64
    np.testing.assert_array_equal(point, [1.5, -2.0, 30.0])
    msg.pose.position.z = math.inf
    with pytest.raises(InputError, match='goal_pose position must be finite'):
        conv.point_from_pose_stamped(msg, FRAME, name='goal_pose')
    msg.pose.position.z = 0.0
    msg.header.frame_id = 'odom'
    with pytest.raises(InputError, match="start frame_id 'odom'.*'map'"):
        conv.point_from_pose_stamped(msg, FRAME, name='start')
