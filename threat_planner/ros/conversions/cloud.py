"""Threat pictures as sensor_msgs/PointCloud2 (float x, y, z, intensity; vx, vy, vz optional).

The optional fields ``vx``, ``vy``, ``vz`` [m/s] (all three or none) give each threat's
velocity in the cloud's frame: its position holds at the cloud's stamp and moves on at
that velocity (issue 44). A cloud without them is a still picture.
"""

from typing import Optional, Tuple

from builtin_interfaces.msg import Time
import numpy as np
from numpy.typing import ArrayLike, NDArray
from sensor_msgs.msg import PointCloud2, PointField

from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import (check_count, check_finite_rows, check_frame,
                                                    check_positive, make_header)

_CLOUD_FIELDS = ('x', 'y', 'z', 'intensity')
_VELOCITY_FIELDS = ('vx', 'vy', 'vz')
# numpy's largest itemsize (a C int): a longer point or row cannot be decoded (nor sent).
_MAX_STEP = 2**31 - 1
_FLOAT_SIZES = {PointField.FLOAT32: 4, PointField.FLOAT64: 8}
_DATATYPE_NAMES = {
    PointField.INT8: 'INT8',
    PointField.UINT8: 'UINT8',
    PointField.INT16: 'INT16',
    PointField.UINT16: 'UINT16',
    PointField.INT32: 'INT32',
    PointField.UINT32: 'UINT32',
    PointField.FLOAT32: 'FLOAT32',
    PointField.FLOAT64: 'FLOAT64',
}


def _cloud_point_dtype(msg: PointCloud2, velocities: bool = False) -> np.dtype:
    """Build the structured dtype of one point from the x, y, z, intensity fields.

    With `velocities`, also from vx, vy, vz when the cloud has them.
    """
    wanted = _CLOUD_FIELDS + (_VELOCITY_FIELDS if velocities else ())
    by_name = {}
    for field in msg.fields:
        if field.name in wanted:
            if field.name in by_name:
                raise InputError(f'PointCloud2 has duplicate field {field.name!r}')
            by_name[field.name] = field
    missing = [name for name in _CLOUD_FIELDS if name not in by_name]
    if missing:
        present = [f.name for f in msg.fields]
        raise InputError(f'PointCloud2 is missing field(s) {missing}; fields are {present}')
    moving = [name for name in _VELOCITY_FIELDS if name in by_name]
    if moving and len(moving) < 3:
        absent = [name for name in _VELOCITY_FIELDS if name not in by_name]
        raise InputError(f'PointCloud2 has velocity field(s) {moving} without {absent}; '
                         'a velocity takes vx, vy and vz')
    names = _CLOUD_FIELDS + tuple(moving)

    byte_order = '>' if msg.is_bigendian else '<'
    formats, offsets, spans = [], [], []
    for name in names:
        field = by_name[name]
        if field.datatype not in _FLOAT_SIZES:
            type_name = _DATATYPE_NAMES.get(field.datatype, 'unknown')
            raise InputError(
                f'PointCloud2 field {name!r} has datatype {type_name} ({field.datatype}); '
                'expected FLOAT32 (7) or FLOAT64 (8)')
        if field.count != 1:
            raise InputError(
                f'PointCloud2 field {name!r} has count {field.count}; expected 1')
        size = _FLOAT_SIZES[field.datatype]
        formats.append(f'{byte_order}f{size}')
        offsets.append(int(field.offset))
        spans.append((int(field.offset), int(field.offset) + size, name))

    # Overlapping coordinates would decode silently as garbage, so refuse them.
    spans.sort()
    for (_, end, name), (start, _, next_name) in zip(spans, spans[1:]):
        if start < end:
            raise InputError(
                f'PointCloud2 fields {name!r} and {next_name!r} overlap '
                f'(offset {start} < end {end})')
    needed = max(end for _, end, _ in spans)
    if msg.point_step < needed:
        raise InputError(
            f'PointCloud2 point_step {msg.point_step} is smaller than the {needed} bytes '
            'its fields need')
    if msg.point_step > _MAX_STEP:
        raise InputError(
            f'PointCloud2 point_step {msg.point_step} is larger than {_MAX_STEP} bytes')
    return np.dtype({'names': list(names), 'formats': formats,
                     'offsets': offsets, 'itemsize': int(msg.point_step)})


def threats_from_pointcloud2(
    msg: PointCloud2,
    expected_frame: str,
    max_points: Optional[int] = None,
) -> Tuple[NDArray[np.float64], NDArray[np.float64]]:
    """
    Decode threat positions and intensities from a PointCloud2 (velocities ignored).

    As :func:`moving_threats_from_pointcloud2` without the velocities.
    """
    positions, intensities, _ = _decode(msg, expected_frame, max_points, False)
    return positions, intensities


def moving_threats_from_pointcloud2(
    msg: PointCloud2,
    expected_frame: str,
    max_points: Optional[int] = None,
) -> Tuple[NDArray[np.float64], NDArray[np.float64], Optional[NDArray[np.float64]]]:
    """
    Decode threat positions, intensities and velocities from a PointCloud2.

    The cloud must carry float fields ``x``, ``y``, ``z`` [m] and ``intensity``
    (FLOAT32 or FLOAT64, ``count`` 1) at any offsets and in any order; other fields
    but ``vx``, ``vy``, ``vz`` [m/s] (float, all three or none) are ignored.
    ``is_bigendian``, ``point_step`` and ``row_step`` (row padding) are
    honoured, and all ``height * width`` points are decoded without a Python loop.

    Parameters
    ----------
    msg : sensor_msgs.msg.PointCloud2
        Threat cloud.
    expected_frame : str
        Frame the positions must be expressed in; compared with ``header.frame_id``.
    max_points : int, optional
        Largest accepted ``height * width``; checked before any decoding so that an
        oversized cloud is refused cheaply.  None (default) means no limit.

    Returns
    -------
    positions : NDArray[np.float64]
        Threat positions, shape (N, 3) [m].
    intensities : NDArray[np.float64]
        Threat intensities, shape (N,), all finite and > 0.
    velocities : NDArray[np.float64] or None
        Threat velocities, shape (N, 3) [m/s], all finite; None for a cloud without
        ``vx``, ``vy``, ``vz``.

    Raises
    ------
    InputError
        On a frame mismatch, too many points, a missing, non-float, multi-count or
        overlapping field, a ``point_step`` or ``row_step`` too small for the layout
        (or over 2**31 - 1 bytes),
        a data length other than ``row_step * height``, non-finite values (a velocity
        field's named) or a non-positive intensity; velocity fields other than all three.

    """
    return _decode(msg, expected_frame, max_points, True)


def _decode(msg: PointCloud2, expected_frame: str, max_points: Optional[int],
            velocities: bool):
    check_frame('PointCloud2', msg.header.frame_id, expected_frame)
    height, width = int(msg.height), int(msg.width)
    check_count('PointCloud2', height * width, max_points)
    point_dtype = _cloud_point_dtype(msg, velocities)
    moving = velocities and 'vx' in point_dtype.names

    row_step = int(msg.row_step)
    if row_step < width * msg.point_step:
        raise InputError(
            f'PointCloud2 row_step {row_step} is smaller than width*point_step = '
            f'{width}*{msg.point_step} = {width * msg.point_step}')
    if len(msg.data) != row_step * height:
        raise InputError(
            f'PointCloud2 data has {len(msg.data)} bytes; row_step*height = '
            f'{row_step}*{height} = {row_step * height}')
    if height * width == 0:
        return (np.empty((0, 3), dtype=np.float64), np.empty(0, dtype=np.float64),
                np.empty((0, 3), dtype=np.float64) if moving else None)

    if row_step > _MAX_STEP:
        raise InputError(f'PointCloud2 row_step {row_step} is larger than {_MAX_STEP} bytes')
    # A row dtype with itemsize row_step skips row padding without copying the buffer.
    row_dtype = np.dtype({'names': ['points'], 'formats': [(point_dtype, (width,))],
                          'offsets': [0], 'itemsize': row_step})
    points = np.frombuffer(msg.data, dtype=row_dtype, count=height)['points'].reshape(-1)
    positions = np.empty((points.shape[0], 3), dtype=np.float64)
    positions[:, 0] = points['x']
    positions[:, 1] = points['y']
    positions[:, 2] = points['z']
    intensities = points['intensity'].astype(np.float64)

    check_finite_rows('PointCloud2', 'positions', positions)
    check_finite_rows('PointCloud2', 'intensities', intensities)
    check_positive('PointCloud2', intensities)
    if not moving:
        return positions, intensities, None
    vel = np.stack([points[name].astype(np.float64) for name in _VELOCITY_FIELDS], axis=1)
    for k, name in enumerate(_VELOCITY_FIELDS):
        bad = ~np.isfinite(vel[:, k])
        if bad.any():
            first = int(np.argmax(bad))
            raise InputError(f'PointCloud2 field {name!r} has {int(bad.sum())} non-finite '
                             f'values (first at index {first}: {float(vel[first, k])!r})')
    return positions, intensities, vel


def pointcloud2_from_threats(
    positions: ArrayLike,
    intensities: ArrayLike,
    frame_id: str,
    stamp: Time,
    velocities: Optional[ArrayLike] = None,
) -> PointCloud2:
    """
    Encode threats as a dense, little-endian PointCloud2.

    Built by hand because sensor_msgs_py is not among the installed wheels.

    Parameters
    ----------
    positions : array_like
        Threat positions, shape (N, 3) [m].
    intensities : array_like
        Threat intensities, shape (N,).
    frame_id : str
        Frame of `positions`.
    stamp : builtin_interfaces.msg.Time
        Header stamp: when the positions hold.
    velocities : array_like, optional
        Threat velocities, shape (N, 3) [m/s]; None for a still picture.

    Returns
    -------
    sensor_msgs.msg.PointCloud2
        Cloud of height 1 and width N with FLOAT32 fields x, y, z, intensity at
        offsets 0, 4, 8, 12 (``point_step`` 16), and vx, vy, vz at 16, 20, 24
        (``point_step`` 28) with velocities; values are rounded to float32.

    Raises
    ------
    InputError
        If the shapes are wrong or disagree.

    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim == 1 and pos.size == 0:
        pos = pos.reshape(0, 3)
    inten = np.asarray(intensities, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise InputError(f'positions must have shape (N, 3), got {pos.shape}')
    if inten.shape != (pos.shape[0],):
        raise InputError(
            f'intensities must have shape ({pos.shape[0]},) to match positions, '
            f'got {inten.shape}')
    names = _CLOUD_FIELDS
    if velocities is not None:
        vel = np.asarray(velocities, dtype=np.float64)
        if vel.size == 0:
            vel = vel.reshape(0, 3)
        if vel.shape != pos.shape:
            raise InputError(f'velocities must have shape {pos.shape} to match positions, '
                             f'got {np.shape(velocities)}')
        names = _CLOUD_FIELDS + _VELOCITY_FIELDS

    point_dtype = np.dtype([(name, '<f4') for name in names])
    packed = np.empty(pos.shape[0], dtype=point_dtype)
    packed['x'], packed['y'], packed['z'] = pos[:, 0], pos[:, 1], pos[:, 2]
    packed['intensity'] = inten
    if velocities is not None:
        packed['vx'], packed['vy'], packed['vz'] = vel[:, 0], vel[:, 1], vel[:, 2]

    msg = PointCloud2()
    msg.header = make_header(frame_id, stamp)
    msg.height = 1
    msg.width = pos.shape[0]
    msg.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, name in enumerate(names)]
    msg.is_bigendian = False
    msg.point_step = point_dtype.itemsize
    msg.row_step = point_dtype.itemsize * pos.shape[0]
    msg.data = packed.tobytes()
    msg.is_dense = bool(np.isfinite(pos).all() and np.isfinite(inten).all())
    return msg
