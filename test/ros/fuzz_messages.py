"""Fuzz inputs for the planner node: encoders of valid clouds and makers of hostile ones.

The encoders are independent of threat_planner.ros.conversions (they build the bytes with
numpy structured dtypes), so a decoding checked against them is a cross-check. Used by
fuzz_cases.py and test_node_fuzz.py.
"""

from __future__ import annotations

import math
from typing import Callable, TYPE_CHECKING

from geometry_msgs.msg import Pose, PoseArray
import numpy as np
from numpy.typing import NDArray
from sensor_msgs.msg import PointCloud2, PointField

from node_harness import pose

if TYPE_CHECKING:
    from fuzz_cases import Fuzzer, Model

MAX_THREATS = 1000
FRAME = 'map'
UINT32_MAX = 2**32 - 1
F32, F64 = PointField.FLOAT32, PointField.FLOAT64
_CODES = {PointField.INT8: 'i1', PointField.UINT8: 'u1', PointField.INT16: 'i2',
          PointField.UINT16: 'u2', PointField.INT32: 'i4', PointField.UINT32: 'u4',
          F32: 'f4', F64: 'f8'}
_CORE = ('x', 'y', 'z', 'intensity')


# --------------------------------------------------------------- message makers


def encode_cloud(positions: NDArray, intensities: NDArray, rng: np.random.Generator
                 ) -> tuple[PointCloud2, NDArray, NDArray]:
    """Encode threats in a random valid layout, independently of conversions.py.

    Returns the cloud and the positions and intensities it holds (rounded to the types).
    """
    n = len(positions)
    extras = list(rng.choice(['rgb', 'ring', 't', 'label'], size=int(rng.integers(0, 3)),
                             replace=False))
    names = list(_CORE) + extras
    rng.shuffle(names)
    endian = '>' if rng.random() < 0.25 else '<'
    fields, formats, offsets, offset = [], [], [], 0
    for name in names:
        if name in _CORE:
            datatype = int(rng.choice([F32, F64]))
        else:
            datatype = int(rng.choice([PointField.UINT8, PointField.INT16,
                                       PointField.UINT32, F32]))
        offset += int(rng.integers(0, 4))
        fields.append(PointField(name=name, offset=offset, datatype=datatype, count=1))
        formats.append(endian + _CODES[datatype])
        offsets.append(offset)
        offset += np.dtype(_CODES[datatype]).itemsize
    point_step = offset + int(rng.integers(0, 8))
    if n == 0:
        height, width = [(0, 0), (1, 0), (3, 0), (0, 4)][int(rng.integers(0, 4))]
    else:
        divisors = [d for d in range(1, n + 1) if n % d == 0]
        height = int(rng.choice(divisors)) if rng.random() < 0.3 else 1
        width = n // height
    row_step = width * point_step + (int(rng.integers(0, 8)) if rng.random() < 0.3 else 0)
    point_dtype = np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                            'itemsize': point_step})
    points = np.zeros(n, point_dtype)
    for k, name in enumerate(('x', 'y', 'z')):
        points[name] = positions[:, k]
    points['intensity'] = intensities
    for name in extras:
        points[name] = rng.integers(0, 100, size=n)
    data = bytearray(rng.integers(0, 256, size=height * row_step, dtype=np.uint8).tobytes())
    raw = points.tobytes()
    for row in range(height):
        chunk = raw[row * width * point_step:(row + 1) * width * point_step]
        data[row * row_step:row * row_step + len(chunk)] = chunk
    order = rng.permutation(len(fields))
    msg = PointCloud2(height=height, width=width, fields=[fields[i] for i in order],
                      is_bigendian=endian == '>', point_step=point_step, row_step=row_step,
                      is_dense=True)
    msg.header.frame_id = FRAME
    msg.data = bytes(data)
    decoded = np.column_stack([points[c].astype(np.float64) for c in ('x', 'y', 'z')]
                              ) if n else np.zeros((0, 3))
    return msg, decoded.reshape(-1, 3), points['intensity'].astype(np.float64)


def plain_cloud(positions: NDArray, intensities: NDArray, size: int = 4) -> PointCloud2:
    """Little-endian floats x, y, z, intensity of `size` bytes, packed (no NaN check)."""
    values = np.column_stack([positions, intensities]).astype(f'<f{size}')
    step = 4 * size
    msg = PointCloud2(height=1, width=len(values), point_step=step,
                      row_step=step * len(values),
                      fields=[PointField(name=n, offset=size * k, datatype=F32 if size == 4
                                         else F64, count=1)
                              for k, n in enumerate(_CORE)], is_dense=False)
    msg.header.frame_id = FRAME
    msg.data = values.tobytes()
    return msg


def pose_array(positions: NDArray, frame: str = FRAME) -> PoseArray:
    """Return a PoseArray of the positions."""
    msg = PoseArray()
    msg.header.frame_id = frame
    msg.poses = [Pose() for _ in positions]
    for p, (x, y, z) in zip(msg.poses, np.asarray(positions, dtype=float).tolist()):
        p.position.x, p.position.y, p.position.z = x, y, z
    return msg


def _mutate(fz: Fuzzer, edit: Callable[[PointCloud2, np.random.Generator], None]):
    msg, _, _ = encode_cloud(*fz.threats(), fz.rng)
    edit(msg, fz.rng)
    return 'threats', msg


def _field(msg: PointCloud2, name: str) -> PointField:
    return next(f for f in msg.fields if f.name == name)


def _core_field(msg: PointCloud2, rng: np.random.Generator) -> PointField:
    return _field(msg, _CORE[int(rng.integers(0, 4))])


def _set_datatype(msg, rng):
    _core_field(msg, rng).datatype = int(rng.choice([0, 1, 2, 3, 4, 5, 6, 9, 200]))


def _set_count(msg, rng):
    _core_field(msg, rng).count = int(rng.choice([0, 2, 3, UINT32_MAX]))


def _drop_field(msg, rng):
    victim = _core_field(msg, rng)
    msg.fields = [f for f in msg.fields if f is not victim]


def _rename_field(msg, rng):
    _core_field(msg, rng).name = str(rng.choice(['X', 'intensity ', 'i', '', 'кarta']))


def _duplicate_field(msg, rng):
    f = _core_field(msg, rng)
    msg.fields = list(msg.fields) + [PointField(name=f.name, offset=f.offset,
                                                datatype=f.datatype, count=1)]


def _overlap(msg, rng):
    a, b = rng.choice(4, size=2, replace=False)
    _field(msg, _CORE[int(a)]).offset = _field(msg, _CORE[int(b)]).offset + 1


def _huge_offset(msg, rng):
    _core_field(msg, rng).offset = int(rng.choice([2**31, UINT32_MAX - 3, 10**6]))


def _nonfinite(array_of: str):
    def make(fz: Fuzzer, model: Model):
        pos, inten = fz.threats()
        k = int(fz.rng.integers(0, len(pos)))
        value = float(fz.rng.choice([math.nan, math.inf, -math.inf]))
        if array_of == 'position':
            pos[k, int(fz.rng.integers(0, 3))] = value
        else:
            inten[k] = value
        return 'threats', plain_cloud(pos, inten)
    return make


def _nonpositive(fz: Fuzzer, model: Model):
    pos, inten = fz.threats()
    inten[int(fz.rng.integers(0, len(pos)))] = float(fz.rng.choice([0.0, -0.0, -1.0, -1e5]))
    return 'threats', plain_cloud(pos, inten)


def _other_frame(fz: Fuzzer, model: Model):
    frame = str(fz.rng.choice(['odom', '', '/map', 'map ', 'MAP', 'base_link', 'карта']))
    roll = int(fz.rng.integers(0, 4))
    if roll == 0:
        msg, _, _ = encode_cloud(*fz.threats(), fz.rng)
        msg.header.frame_id = frame
        return 'threats', msg
    if roll == 1:
        return 'threat_poses', pose_array(fz.threats()[0], frame)
    return ('start', 'goal_pose')[roll - 2], pose(fz.rng.uniform(0, 100, 3), frame)


def _huge_claim(fz: Fuzzer, model: Model):
    msg, _, _ = encode_cloud(*fz.threats(), fz.rng)
    width, height = [(10**6, 1), (1, 10**6), (UINT32_MAX, UINT32_MAX), (MAX_THREATS + 1, 1),
                     (65536, 65536)][int(fz.rng.integers(0, 5))]
    msg.width, msg.height = width, height
    return 'threats', msg


def _too_many(fz: Fuzzer, model: Model):
    pos, inten = fz.threats(MAX_THREATS + 1)
    if fz.rng.random() < 0.5:
        return 'threats', plain_cloud(pos, inten)
    return 'threat_poses', pose_array(pos)


def _bad_pose(fz: Fuzzer, model: Model):
    rng = fz.rng
    topic = 'threat_poses' if rng.random() < 0.3 else str(rng.choice(['start', 'goal_pose']))
    if topic == 'threat_poses':
        pos = fz.threats()[0]
        pos[int(rng.integers(0, len(pos))), int(rng.integers(0, 3))] = float(
            rng.choice([math.nan, math.inf]))
        return topic, pose_array(pos)
    point = rng.uniform(0.0, 100.0, size=3)
    roll = int(rng.integers(0, 3))
    if roll == 0:
        point[int(rng.integers(0, 3))] = float(rng.choice([math.nan, math.inf, -math.inf]))
    elif roll == 1:
        point[int(rng.integers(0, 3))] = float(rng.choice([-0.5, 100.5, -1e9, 1e300]))
    elif model.threats is not None and len(model.threats):
        point = model.threats.positions[int(rng.integers(0, len(model.threats)))].copy()
    else:
        point[0] = -1.0
    return topic, pose(point)


def _threat_on_end(fz: Fuzzer, model: Model):
    pos, inten = fz.threats()
    pos[int(fz.rng.integers(0, len(pos)))] = model.start if fz.rng.random() < 0.5 \
        else model.goal
    return 'threats', plain_cloud(pos, inten, size=8)  # float64: exactly on the point


MAKERS: dict[str, Callable[[Fuzzer, Model], tuple[str, object]]] = {
    'truncated_data': lambda fz, m: _mutate(fz, lambda msg, rng: setattr(
        msg, 'data', bytes(msg.data)[:-int(rng.integers(1, len(msg.data) + 1))])),
    'extended_data': lambda fz, m: _mutate(fz, lambda msg, rng: setattr(
        msg, 'data', bytes(msg.data) + bytes(int(rng.integers(1, 64))))),
    'point_step_too_small': lambda fz, m: _mutate(fz, lambda msg, rng: setattr(
        msg, 'point_step', int(rng.integers(0, max(f.offset for f in msg.fields))))),
    'row_step_too_small': lambda fz, m: _mutate(fz, lambda msg, rng: setattr(
        msg, 'row_step', int(rng.integers(0, msg.width * msg.point_step)))),
    'field_datatype': lambda fz, m: _mutate(fz, _set_datatype),
    'field_count': lambda fz, m: _mutate(fz, _set_count),
    'field_missing': lambda fz, m: _mutate(fz, _drop_field),
    'field_renamed': lambda fz, m: _mutate(fz, _rename_field),
    'field_duplicated': lambda fz, m: _mutate(fz, _duplicate_field),
    'fields_overlap': lambda fz, m: _mutate(fz, _overlap),
    'field_huge_offset': lambda fz, m: _mutate(fz, _huge_offset),
    'no_fields': lambda fz, m: _mutate(fz, lambda msg, rng: setattr(msg, 'fields', [])),
    'nonfinite_position': _nonfinite('position'),
    'nonfinite_intensity': _nonfinite('intensity'),
    'nonpositive_intensity': _nonpositive,
    'other_frame': _other_frame,
    'huge_size_claim': _huge_claim,
    'too_many_threats': _too_many,
    'bad_pose': _bad_pose,
    'threat_on_start_or_goal': _threat_on_end,
}
BAD_KINDS = sorted(MAKERS)


def random_layout(rng: np.random.Generator) -> PointCloud2:
    """Fields, sizes and bytes drawn at random; mostly invalid, sometimes a valid cloud."""
    pool = ['x', 'y', 'z', 'intensity', 'x', 'y', 'z', 'intensity', 'rgb', '']
    fields = [PointField(name=str(rng.choice(pool)),
                         offset=int(rng.choice([0, 4, 8, 12, 16, int(rng.integers(0, 64)),
                                                UINT32_MAX])),
                         datatype=int(rng.choice([7, 7, 8, int(rng.integers(0, 10))])),
                         count=int(rng.choice([1, 1, 1, 0, 2])))
              for _ in range(int(rng.integers(0, 7)))]
    point_step = int(rng.choice([16, 16, 32, int(rng.integers(0, 64)), UINT32_MAX]))
    width, height = int(rng.integers(0, 7)), int(rng.choice([0, 1, 1, 1, 2, 3]))
    row_step = max(0, min(UINT32_MAX, width * point_step + int(rng.choice([0, 0, -4, 4]))))
    size = row_step * height
    if size > 4096:
        size = int(rng.integers(0, 4096))
    size = max(0, size + int(rng.choice([0, 0, 0, -1, 1])))
    if rng.random() < 0.7:
        # Plausible float32 values make a valid decoding possible.
        data = rng.uniform(1.0, 99.0, size=(size + 3) // 4).astype('<f4').tobytes()[:size]
    else:
        data = rng.integers(0, 256, size=size, dtype=np.uint8).tobytes()
    msg = PointCloud2(height=height, width=width, fields=fields,
                      is_bigendian=bool(rng.random() < 0.2), point_step=point_step,
                      row_step=row_step, is_dense=bool(rng.random() < 0.5))
    msg.header.frame_id = FRAME
    msg.data = data
    return msg


def million_cloud(rng: np.random.Generator) -> PointCloud2:
    """Return a real 10^6-point cloud (16 MB), far over max_threats."""
    n = 10**6
    return plain_cloud(rng.uniform(0.0, 100.0, size=(n, 3)), np.full(n, 1e5))


def huge_step(point_step: int, width: int, height: int, row_step: int) -> PointCloud2:
    """Return a cloud whose sizes numpy cannot make a dtype of (once a ValueError in the node)."""
    msg = plain_cloud(np.full((1, 3), 50.0), np.ones(1))
    msg.point_step, msg.width, msg.height, msg.row_step = point_step, width, height, row_step
    msg.data = bytes(16) if width * height else b''
    return msg
