"""Threat pictures as sensor_msgs/PointCloud2 (float x, y, z, intensity)."""

from typing import Optional, Tuple

from builtin_interfaces.msg import Time
import numpy as np
from numpy.typing import ArrayLike, NDArray
from sensor_msgs.msg import PointCloud2, PointField

from threat_planner.errors import InputError
from threat_planner.ros.conversions._common import (check_count, check_finite_rows, check_frame,
                                                    check_positive, make_header)

_CLOUD_FIELDS = ('x', 'y', 'z', 'intensity')
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


def _cloud_point_dtype(msg: PointCloud2) -> np.dtype:
    """Build the structured dtype of one point from the x, y, z, intensity fields."""
    by_name = {}
    for field in msg.fields:
        if field.name in _CLOUD_FIELDS:
            if field.name in by_name:
                raise InputError(f'PointCloud2 has duplicate field {field.name!r}')
            by_name[field.name] = field
    missing = [name for name in _CLOUD_FIELDS if name not in by_name]
    if missing:
        present = [f.name for f in msg.fields]
        raise InputError(f'PointCloud2 is missing field(s) {missing}; fields are {present}')

    byte_order = '>' if msg.is_bigendian else '<'
    formats, offsets, spans = [], [], []
    for name in _CLOUD_FIELDS:
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
    return np.dtype({'names': list(_CLOUD_FIELDS), 'formats': formats,
                     'offsets': offsets, 'itemsize': int(msg.point_step)})


def threats_from_pointcloud2(
    msg: PointCloud2,
    expected_frame: str,
    max_points: Optional[int] = None,
) -> Tuple[NDArray[np.float64], NDArray[np.float64]]:
    """
    Decode threat positions and intensities from a PointCloud2.

    The cloud must carry float fields ``x``, ``y``, ``z`` [m] and ``intensity``
    (FLOAT32 or FLOAT64, ``count`` 1) at any offsets and in any order; other fields
    are ignored.  ``is_bigendian``, ``point_step`` and ``row_step`` (row padding) are
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

    Raises
    ------
    InputError
        On a frame mismatch, too many points, a missing, non-float, multi-count or
        overlapping field, a ``point_step`` or ``row_step`` too small for the layout
        (or over 2**31 - 1 bytes),
        a data length other than ``row_step * height``, non-finite values or a
        non-positive intensity.

    """
    check_frame('PointCloud2', msg.header.frame_id, expected_frame)
    height, width = int(msg.height), int(msg.width)
    check_count('PointCloud2', height * width, max_points)
    point_dtype = _cloud_point_dtype(msg)

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
        return np.empty((0, 3), dtype=np.float64), np.empty(0, dtype=np.float64)

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
    return positions, intensities


def pointcloud2_from_threats(
    positions: ArrayLike,
    intensities: ArrayLike,
    frame_id: str,
    stamp: Time,
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
        Header stamp.

    Returns
    -------
    sensor_msgs.msg.PointCloud2
        Cloud of height 1 and width N with FLOAT32 fields x, y, z, intensity at
        offsets 0, 4, 8, 12 (``point_step`` 16); values are rounded to float32.

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

    point_dtype = np.dtype([(name, '<f4') for name in _CLOUD_FIELDS])
    packed = np.empty(pos.shape[0], dtype=point_dtype)
    packed['x'], packed['y'], packed['z'] = pos[:, 0], pos[:, 1], pos[:, 2]
    packed['intensity'] = inten

    msg = PointCloud2()
    msg.header = make_header(frame_id, stamp)
    msg.height = 1
    msg.width = pos.shape[0]
    msg.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, name in enumerate(_CLOUD_FIELDS)]
    msg.is_bigendian = False
    msg.point_step = point_dtype.itemsize
    msg.row_step = point_dtype.itemsize * pos.shape[0]
    msg.data = packed.tobytes()
    msg.is_dense = bool(np.isfinite(pos).all() and np.isfinite(inten).all())
    return msg
