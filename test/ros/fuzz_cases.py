"""Fuzz cases for the planner node: the model of its state, the oracle and the draw.

A Case is one input with its intent ('good', 'bad' or 'either'); the oracle runs the
node's own validation on the Model of what the node should hold; draw_cases gives the
seeded sequence (see test_node_fuzz.py for how they are sent and checked).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import os
from typing import Callable, Optional

from builtin_interfaces.msg import Time
import numpy as np
from numpy.typing import NDArray
from sensor_msgs.msg import PointCloud2

from fuzz_messages import (_mutate, BAD_KINDS, encode_cloud, FRAME, huge_step, MAKERS,
                           MAX_THREATS, million_cloud, plain_cloud, pose_array, random_layout,
                           UINT32_MAX)
from node_harness import pose
from threat_planner.core.planner import check_endpoints
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError
from threat_planner.ros.conversions import (point_from_pose_stamped, threats_from_pointcloud2,
                                            threats_from_pose_array)
from threat_planner.ros.parameters import PARAMETER_DEFAULTS, settings_from_parameters

# FUZZ_SEED and FUZZ_MESSAGES explore beyond the CI run (same checks, other draws).
SEED = int(os.environ.get('FUZZ_SEED', 20251125))
N_MESSAGES = int(os.environ.get('FUZZ_MESSAGES', 300))
PARAMS = {'method': 'paper', 'n_points': 20, 'max_threats': MAX_THREATS}
SETTINGS = settings_from_parameters({**PARAMETER_DEFAULTS, **PARAMS})
BOX = SETTINGS.box
DEFAULT_INTENSITY = float(PARAMETER_DEFAULTS['default_intensity'])

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
        """Return a good picture in a random layout (10 % empty)."""
        if n is None and self.rng.random() < 0.1:
            n = 0
        msg, pos, inten = encode_cloud(*self.threats(n), self.rng)
        return Case('good_cloud' if len(pos) else 'empty_cloud', 'threats', msg, 'good',
                    (pos, inten))

    def good_poses(self) -> Case:
        """Return a good PoseArray picture (default intensities)."""
        pos, _ = self.threats()
        return Case('good_poses', 'threat_poses', pose_array(pos), 'good',
                    (pos, np.full(len(pos), DEFAULT_INTENSITY)))

    def good_end(self, model: Model) -> Case:
        """Return a good start or goal, on a face of the box."""
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
        """Return a random layout, a byte-flipped cloud or extreme but finite values."""
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


#: Fixed hostile cases placed among the random ones: (label, intent, maker).
SPECIALS: list[tuple[str, str, Callable[[np.random.Generator], PointCloud2]]] = [
    ('million_points', 'bad', million_cloud),
    ('point_step_2^31', 'bad', lambda rng: huge_step(2**31 + 16, 1, 1, 2**31 + 16)),
    ('empty_point_step_max', 'either', lambda rng: huge_step(UINT32_MAX, 0, 1, 0)),
    ('empty_row_step_max', 'either', lambda rng: huge_step(16, 1, 0, UINT32_MAX)),
    ('empty_width_2^31', 'either', lambda rng: huge_step(16, 2**31, 0, UINT32_MAX)),
]


def draw_cases(n: int, seed: int) -> list[Callable[[Model], Case]]:
    """Return the sequence of case makers: a good picture first, then a seeded mix."""
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
    """Return a unique stamp per input; a few are odd (negative, int32 max, nanosec >= 1e9)."""
    roll = rng.random()
    if roll < 0.03:
        return Time(sec=-1 - k, nanosec=k)
    if roll < 0.06:
        return Time(sec=2**31 - 1 - k, nanosec=k)
    if roll < 0.09:
        return Time(sec=100_000 + k, nanosec=UINT32_MAX - k)
    return Time(sec=100_000 + k, nanosec=k)
