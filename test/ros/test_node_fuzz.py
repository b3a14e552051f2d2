"""Fuzz test of the planner node: hundreds of malformed, hostile and good inputs in a row.

One planner node process (method 'paper', recording on) gets ``N_MESSAGES`` inputs drawn
with a fixed seed: good threat pictures in random but valid PointCloud2 layouts (field
order, FLOAT32/FLOAT64, padding fields and bytes, row padding, big endian, several rows),
good PoseArrays, starts and goals, and bad ones (truncated or extended data, wrong
point_step or row_step, missing, duplicated, overlapping, multi-count or integer fields,
huge offsets and sizes, a 10^6-point cloud, other frame ids, NaN/inf positions and poses,
zero or negative intensities, too many threats, start or goal outside the box or on a
threat), plus random field layouts, byte-flipped clouds and extreme values (threats 1e30 m
away, intensities 1e-45 or 3.4e38) whose fate an oracle decides.

The oracle is the node's own validation run in this process on the same state (the node
is a process boundary away, so this checks transport and the node's bookkeeping), and for
the intended-good clouds the decoded values are also checked against an independent
encoder. Each input is sent only after the previous one is answered, so no update is
coalesced and every one must get its own ``plan_info``:

* a good input: status OK or WARN, ``input_seq`` one more than the last, a ``path`` with
  its stamp that starts at the current start and ends at the current goal (and, for the
  intended-good ones, equals the library's plan for the same decoded threats);
* a bad input: status ERROR with the reason, the node still alive;
* every 25 inputs and at the end: the process is alive and its parameter service answers.

An accepted 'either' picture may still fail to plan (a threat 1e20 m or more outside the
box makes scipy's Qhull fail in the partition): that is an ERROR answer too, counted
apart as ``accepted_but_not_planned``. At the end the recording must hold every input,
by stamp. Set ``THREAT_PLANNER_RESULTS``
to a folder to also write the counts there as ``reliability_fuzz.json``; ``FUZZ_SEED``
and ``FUZZ_MESSAGES`` draw other or longer sequences.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import json
import math
import os
from pathlib import Path
import signal
import threading
import time
from typing import Callable, Optional

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Path as PathMsg
import numpy as np
from numpy.typing import NDArray
import pytest
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import PointCloud2, PointField

from node_harness import (domain_id, info, planner_command, pose, RosClient, start_process,
                          stop_process, VOLATILE)
from threat_planner.bag import read_messages
from threat_planner.core.planner import check_endpoints, plan
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError
from threat_planner.ros.conversions import (path_from_msg, point_from_pose_stamped, stamp_to_ns,
                                            threats_from_pointcloud2, threats_from_pose_array)
from threat_planner.ros.parameters import PARAMETER_DEFAULTS, settings_from_parameters

DOMAIN = domain_id(16)
NS = '/fuzz'
# FUZZ_SEED and FUZZ_MESSAGES explore beyond the CI run (same checks, other draws).
SEED = int(os.environ.get('FUZZ_SEED', 20251125))
N_MESSAGES = int(os.environ.get('FUZZ_MESSAGES', 300))
MAX_THREATS = 1000
FRAME = 'map'
PARAMS = {'method': 'paper', 'n_points': 20, 'max_threats': MAX_THREATS}
SETTINGS = settings_from_parameters({**PARAMETER_DEFAULTS, **PARAMS})
BOX = SETTINGS.box
DEFAULT_INTENSITY = float(PARAMETER_DEFAULTS['default_intensity'])
#: Longest wait for one answer [s]; the 10^6-point cloud is the slow one (16 MB).
ANSWER_TIMEOUT_S = 30.0
UINT32_MAX = 2**32 - 1

F32, F64 = PointField.FLOAT32, PointField.FLOAT64
_CODES = {PointField.INT8: 'i1', PointField.UINT8: 'u1', PointField.INT16: 'i2',
          PointField.UINT16: 'u2', PointField.INT32: 'i4', PointField.UINT32: 'u4',
          F32: 'f4', F64: 'f8'}
_CORE = ('x', 'y', 'z', 'intensity')


# ------------------------------------------------------------------ the model


@dataclass(frozen=True)
class Model:
    """What the node should hold: start, goal and threat picture (None before the first)."""

    start: NDArray
    goal: NDArray
    threats: Optional[ThreatField] = None
    #: The picture came from an 'either' case (garbage or extreme values): the library may
    #: fail to plan it (see the module docstring), so later starts and goals count as
    #: 'either' too until a good picture replaces it.
    exotic: bool = False


@dataclass
class Case:
    """One input: where it goes, what it is, and what the oracle expects of it."""

    label: str
    topic: str
    msg: object
    intent: str  # 'good', 'bad' or 'either' (the oracle decides)
    expected: Optional[tuple[NDArray, NDArray]] = None  # independent decoding of a cloud
    accept: bool = False
    reason: str = ''
    after: Optional[Model] = None


def oracle(case: Case, model: Model) -> None:
    """Run the node's validation of `case` on `model`; fill in accept, reason, after."""
    msg = case.msg
    try:
        if case.topic in ('threats', 'threat_poses'):
            if case.topic == 'threats':
                count = int(msg.width) * int(msg.height)
                if count > MAX_THREATS:
                    raise InputError(f'PointCloud2 has {count} threats, more than '
                                     f'max_threats={MAX_THREATS}')
                positions, intensities = threats_from_pointcloud2(msg, FRAME)
            else:
                if len(msg.poses) > MAX_THREATS:
                    raise InputError(f'PoseArray has {len(msg.poses)} threats')
                positions, intensities = threats_from_pose_array(msg, FRAME,
                                                                 DEFAULT_INTENSITY)
            threats = ThreatField.from_arrays(positions, intensities)
            check_endpoints(model.start, model.goal, BOX, threats)
            case.after = replace(model, threats=threats, exotic=case.intent == 'either')
        else:
            name = 'start' if case.topic == 'start' else 'goal_pose'
            point = point_from_pose_stamped(msg, FRAME, name)
            known = model.threats if model.threats is not None else _NO_THREATS
            if case.topic == 'start':
                check_endpoints(point, model.goal, BOX, known)
                case.after = replace(model, start=point)
            else:
                check_endpoints(model.start, point, BOX, known)
                case.after = replace(model, goal=point)
        case.accept = True
    except InputError as exc:
        case.reason = str(exc)
    except Exception as exc:  # noqa: B902 - the node reports these as 'cannot read'
        case.reason = f'cannot read: {type(exc).__name__}: {exc}'


_NO_THREATS = ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0))


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
    """PoseArray of the positions."""
    msg = PoseArray()
    msg.header.frame_id = frame
    msg.poses = [Pose() for _ in positions]
    for p, (x, y, z) in zip(msg.poses, np.asarray(positions, dtype=float).tolist()):
        p.position.x, p.position.y, p.position.z = x, y, z
    return msg


class Fuzzer:
    """Draws cases from a seeded generator; knows the current model for start-on-threat."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def threats(self, n: Optional[int] = None) -> tuple[NDArray, NDArray]:
        """Random positions inside the box and intensities 1e3..1e6."""
        rng = self.rng
        n = int(rng.integers(1, 31)) if n is None else n
        return (rng.uniform(2.0, 98.0, size=(n, 3)),
                10.0 ** rng.uniform(3.0, 6.0, size=n))

    def good_cloud(self, n: Optional[int] = None) -> Case:
        """A good picture in a random layout (10 % empty)."""
        if n is None and self.rng.random() < 0.1:
            n = 0
        msg, pos, inten = encode_cloud(*self.threats(n), self.rng)
        return Case('good_cloud' if len(pos) else 'empty_cloud', 'threats', msg, 'good',
                    (pos, inten))

    def good_poses(self) -> Case:
        pos, _ = self.threats()
        return Case('good_poses', 'threat_poses', pose_array(pos), 'good',
                    (pos, np.full(len(pos), DEFAULT_INTENSITY)))

    def good_end(self, model: Model) -> Case:
        topic = 'start' if self.rng.random() < 0.5 else 'goal_pose'
        point = self.rng.uniform(0.0, 100.0, size=3)
        point[int(self.rng.integers(0, 3))] = float(self.rng.choice([0.0, 100.0]))
        return Case(f'good_{topic}', topic, pose(point), 'good')

    def bad(self, model: Model) -> Case:
        """One of the hand-made bad inputs."""
        rng = self.rng
        kind = BAD_KINDS[int(rng.integers(0, len(BAD_KINDS)))]
        return Case(kind, *MAKERS[kind](self, model), 'bad')

    def either(self) -> Case:
        """A random layout, a byte-flipped cloud or extreme but finite values."""
        rng = self.rng
        roll = rng.random()
        if roll < 0.5:
            return Case('random_layout', 'threats', random_layout(rng), 'either')
        if roll < 0.6:
            # Valid again if the padding allows it, then decoded misaligned.
            _, msg = _mutate(self, lambda msg, rng: setattr(
                msg, 'point_step', msg.point_step + int(rng.choice([-1, 1, 8, 2**31]))))
            return Case('point_step_changed', 'threats', msg, 'either')
        if roll < 0.8:
            msg, _, _ = encode_cloud(*self.threats(), rng)
            msg.is_bigendian = not msg.is_bigendian
            return Case('endian_flipped', 'threats', msg, 'either')
        pos, inten = self.threats()
        k = int(rng.integers(0, len(pos)))
        which = int(rng.integers(0, 4))
        if which == 0:
            inten[k] = float(rng.choice([1e-45, 1e-30, 3.4e38]))
        elif which == 1:
            pos[k] = rng.uniform(-1e30, 1e30, size=3)
        elif which == 2:
            pos[:] = 50.0 + rng.normal(scale=1e-6, size=pos.shape)
        else:
            pos[:, 2] = 37.5
        return Case('extreme_values', 'threats', plain_cloud(pos, inten), 'either')


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
    """A real 10^6-point cloud (16 MB), far over max_threats."""
    n = 10**6
    return plain_cloud(rng.uniform(0.0, 100.0, size=(n, 3)), np.full(n, 1e5))


def huge_step(point_step: int, width: int, height: int, row_step: int) -> PointCloud2:
    """A cloud whose sizes numpy cannot make a dtype of (once a ValueError in the node)."""
    msg = plain_cloud(np.full((1, 3), 50.0), np.ones(1))
    msg.point_step, msg.width, msg.height, msg.row_step = point_step, width, height, row_step
    msg.data = bytes(16) if width * height else b''
    return msg


#: Fixed hostile cases placed among the random ones: (label, intent, maker).
SPECIALS: list[tuple[str, str, Callable[[np.random.Generator], PointCloud2]]] = [
    ('million_points', 'bad', million_cloud),
    ('point_step_2^31', 'bad', lambda rng: huge_step(2**31 + 16, 1, 1, 2**31 + 16)),
    ('empty_point_step_max', 'either', lambda rng: huge_step(UINT32_MAX, 0, 1, 0)),
    ('empty_row_step_max', 'either', lambda rng: huge_step(16, 1, 0, UINT32_MAX)),
    ('empty_width_2^31', 'either', lambda rng: huge_step(16, 2**31, 0, UINT32_MAX)),
]


def draw_cases(n: int, seed: int) -> list[Callable[[Model], Case]]:
    """The sequence of case makers: a good picture first, then a seeded mix."""
    fz = Fuzzer(seed)
    makers: list[Callable[[Model], Case]] = [lambda m: fz.good_cloud(10)]
    special_at = {n * (j + 1) // (len(SPECIALS) + 1): s for j, s in enumerate(SPECIALS)}
    for k in range(1, n):
        if k in special_at:
            label, intent, make = special_at[k]
            makers.append(lambda m, label=label, intent=intent, make=make: Case(
                label, 'threats', make(fz.rng), intent))
            continue
        roll = fz.rng.random()
        if roll < 0.25:
            makers.append(lambda m: fz.good_cloud())
        elif roll < 0.30:
            makers.append(lambda m: fz.good_poses())
        elif roll < 0.38:
            makers.append(fz.good_end)
        elif roll < 0.85:
            makers.append(fz.bad)
        else:
            makers.append(lambda m: fz.either())
    return makers


def stamp_for(k: int, rng: np.random.Generator) -> Time:
    """A unique stamp per input; a few are odd (negative, int32 max, nanosec >= 1e9)."""
    roll = rng.random()
    if roll < 0.03:
        return Time(sec=-1 - k, nanosec=k)
    if roll < 0.06:
        return Time(sec=2**31 - 1 - k, nanosec=k)
    if roll < 0.09:
        return Time(sec=100_000 + k, nanosec=UINT32_MAX - k)
    return Time(sec=100_000 + k, nanosec=k)


# ---------------------------------------------------------------------- the test


@dataclass
class Tally:
    """Counts of the run."""

    tried: int = 0
    good: int = 0
    bad: int = 0
    either_planned: int = 0
    either_refused: int = 0
    crashes: int = 0
    good_without_plan: list = field(default_factory=list)
    bad_not_reported: list = field(default_factory=list)
    wrong_answers: list = field(default_factory=list)
    accepted_but_not_planned: list = field(default_factory=list)
    unclean_rejections: list = field(default_factory=list)
    parameter_checks: int = 0
    parameter_failures: int = 0
    labels: dict = field(default_factory=dict)
    seconds: float = 0.0


@pytest.fixture(scope='module')
def client():
    c = RosClient(DOMAIN, 'fuzz_client')
    yield c
    c.close()


def parameter_ok(params: AsyncParameterClient, timeout: float = 5.0) -> bool:
    """Whether the node answers a parameter get within `timeout`."""
    done = threading.Event()
    future = params.get_parameters(['max_threats'])
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        return False
    values = future.result().values
    return len(values) == 1 and values[0].integer_value == MAX_THREATS


def check_plan(client, case: Case, model: Model, values: dict, stamp: Time,
               paths_before: int) -> Optional[str]:
    """What is wrong with the plan answering `case` (`model` after it), or None."""
    if values['level'] not in ('OK', 'WARN'):
        return f'level {values["level"]}'
    path = client.wait_for(f'{NS}/path', lambda m: m.header.stamp == stamp, 10.0,
                           after=paths_before)
    points = path_from_msg(path)
    if not (np.allclose(points[0], model.start, atol=1e-6)
            and np.allclose(points[-1], model.goal, atol=1e-6)):
        return f'path {points[0].tolist()}..{points[-1].tolist()} does not join start and goal'
    if int(values['threats']) != len(model.threats):
        return f'{values["threats"]} threats planned, {len(model.threats)} sent'
    if case.intent == 'good':
        expected = plan(model.threats, model.start, model.goal, BOX, SETTINGS.config)
        if not np.allclose(points, expected.path, rtol=0.0, atol=1e-6):
            return 'path differs from the library plan of the same threats'
    return None


def test_fuzzed_inputs_are_each_answered(client, tmp_path):
    record = tmp_path / 'fuzz.mcap'
    log = tmp_path / 'node.log'
    proc = start_process(planner_command(NS, {**PARAMS, 'record': str(record)}), DOMAIN, log)
    for name, msg_type in (('plan_info', DiagnosticArray), ('path', PathMsg)):
        client.subscribe(f'{NS}/{name}', msg_type)
    pubs = {'threats': client.publisher(f'{NS}/threats', PointCloud2),
            'threat_poses': client.publisher(f'{NS}/threat_poses', PoseArray),
            'start': client.publisher(f'{NS}/start', PoseStamped, VOLATILE),
            'goal_pose': client.publisher(f'{NS}/goal_pose', PoseStamped, VOLATILE)}
    for pub in pubs.values():
        client.wait_matched(pub, timeout=30.0)
    params = AsyncParameterClient(client.node, f'{NS}/threat_planner')
    assert params.wait_for_services(timeout_sec=30.0)

    model = Model(SETTINGS.start, SETTINGS.goal)
    stamp_rng = np.random.default_rng(SEED + 1)
    tally = Tally()
    sent_stamps = []
    t0 = time.monotonic()
    try:
        for k, make in enumerate(draw_cases(N_MESSAGES, SEED)):
            case = make(model)
            if model.exotic and case.topic in ('start', 'goal_pose'):
                case.intent = 'either'
            oracle(case, model)
            if case.intent == 'good':
                assert case.accept, (case.label, case.reason)
                if case.expected is not None and case.topic == 'threats':
                    pos, inten = threats_from_pointcloud2(case.msg, FRAME)
                    np.testing.assert_array_equal(pos, case.expected[0])
                    np.testing.assert_array_equal(inten, case.expected[1])
            elif case.intent == 'bad':
                assert not case.accept, case.label
            if case.reason.startswith('cannot read:'):
                tally.unclean_rejections.append((case.label, case.reason))
            stamp = stamp_for(k, stamp_rng)
            case.msg.header.stamp = stamp
            stamp_ns = stamp_to_ns(stamp)
            sent_stamps.append((case.topic, stamp_ns))
            tally.tried += 1
            tally.labels[case.label] = tally.labels.get(case.label, 0) + 1
            infos_before = client.count(f'{NS}/plan_info')
            paths_before = client.count(f'{NS}/path')
            pubs[case.topic].publish(case.msg)
            try:
                answer = client.wait_for(
                    f'{NS}/plan_info', lambda m: int(info(m)['input_stamp_ns']) == stamp_ns
                    and int(info(m)['input_seq']) == k + 1, ANSWER_TIMEOUT_S,
                    after=infos_before)
            except TimeoutError:
                answer = None
            if proc.poll() is not None:
                tally.crashes += 1
                break
            values = info(answer) if answer is not None else None
            if case.accept:
                tally.good += case.intent == 'good'
                planned_model = case.after
                model = case.after
                if values is None or values['level'] == 'ERROR':
                    what = (case.label, k, values and values['message'][:200])
                    if case.intent == 'good':
                        tally.good_without_plan.append(what)
                    else:
                        tally.accepted_but_not_planned.append(what)
                    continue
                problem = check_plan(client, case, planned_model, values, stamp,
                                     paths_before)
                if problem:
                    tally.wrong_answers.append((case.label, k, problem))
                tally.either_planned += case.intent == 'either'
            else:
                tally.bad += case.intent == 'bad'
                tally.either_refused += case.intent == 'either'
                if values is None or values['level'] != 'ERROR' or not values.get('error') \
                        or f'{NS}/{case.topic}' not in values['message']:
                    tally.bad_not_reported.append((case.label, k, values))
            if k % 25 == 0:
                tally.parameter_checks += 1
                tally.parameter_failures += not parameter_ok(params)
        tally.parameter_checks += 1
        tally.parameter_failures += not parameter_ok(params)
        tally.seconds = time.monotonic() - t0
    finally:
        code = stop_process(proc, signal.SIGINT)
    tally.crashes += code != 0

    recorded = [(m.topic, stamp_to_ns(m.msg.header.stamp)) for m in read_messages(record)
                if m.topic.rsplit('/', 1)[-1] in pubs]
    summary = {**tally.__dict__, 'exit_code': code, 'recorded_inputs': len(recorded),
               'inputs_missing_from_recording': len(
                   set((f'{NS}/{t}', s) for t, s in sent_stamps) - set(recorded))}
    print(json.dumps(summary, indent=1, default=str))
    out = os.environ.get('THREAT_PLANNER_RESULTS')
    if out:
        Path(out, 'reliability_fuzz.json').write_text(
            json.dumps(summary, indent=2, default=str, sort_keys=True) + '\n')

    assert tally.tried == N_MESSAGES, log.read_text()
    assert tally.crashes == 0 and code == 0, log.read_text()[-5000:]
    assert tally.good_without_plan == []
    assert tally.bad_not_reported == []
    assert tally.wrong_answers == []
    assert tally.parameter_failures == 0
    assert tally.unclean_rejections == []
    assert summary['inputs_missing_from_recording'] == 0
    assert tally.good > 50 and tally.bad > 100
