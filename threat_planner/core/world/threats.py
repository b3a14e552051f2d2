"""Threat model (paper Section 3.1) and the flight box.

A radar i at p_i with transmitter power F_i sees a target at range R with received power
P = Q F_i / R^4 (eq. 1-3). The planner only needs positions and intensities F_i, plus a
spatial index so that far threats can be cut off with a stated error bound.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from itertools import chain
import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core._vector import vector_length
from threat_planner.errors import InputError

if TYPE_CHECKING:  # imported where a tree is built: scipy.spatial is 0.3 s to import
    from scipy.spatial import cKDTree

    from threat_planner.core.world.far_field import FarField


#: Largest coordinate magnitude accepted anywhere [m]. Beyond it double-precision geometry
#: stops being geometry: at 1e12 m neighbouring doubles are 0.1 mm apart and d^4 of the
#: threat cost stays below 1e49, while at 1e154 m d^4 overflows and Qhull's and the
#: search's arithmetic lose every metre. 1e12 m (7 au) is far beyond any flight.
COORDINATE_LIMIT_M = 1.0e12


def check_coordinates(name: str, arr: NDArray) -> None:
    """Raise InputError unless every coordinate of `arr` is within the limit.

    Parameters
    ----------
    name : str
        Field name for the message.
    arr : NDArray
        Finite coordinates (3,) or (N, 3) [m].

    """
    big = np.abs(arr) > COORDINATE_LIMIT_M
    if big.any():
        rows = big.reshape(-1, 3).any(axis=1) if arr.ndim > 1 else big[:1]
        first = int(np.argmax(rows))
        where = f'{name}[{first}]' if arr.ndim > 1 else name
        value = float(np.abs(arr.reshape(-1, 3)[first]).max())
        raise InputError(f'{where}: coordinate {value:g} m is too large for double-precision '
                         f'geometry; |x|, |y|, |z| must be <= {COORDINATE_LIMIT_M:g} m')


def _finite_array(name: str, value: ArrayLike, shape_tail: tuple[int, ...]) -> NDArray:
    """Convert to a float array of shape (..., *shape_tail) with only finite values."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputError(f'{name}: not numeric ({exc})') from None
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        if not (arr.size == 0 and shape_tail):
            raise InputError(f'{name}: expected shape (N, {", ".join(map(str, shape_tail))})'
                             f' or (N,), got {arr.shape}')
        arr = arr.reshape((0,) + shape_tail)
    bad = ~np.isfinite(arr)
    if bad.any():
        rows = bad.reshape(len(arr), -1).any(axis=1)
        first = int(np.argmax(rows))
        raise InputError(f'{name}[{first}]: not finite ({arr[first].tolist()}); '
                         f'{int(rows.sum())} bad entries')
    return arr


def as_point(name: str, value: ArrayLike) -> NDArray:
    """Validate one finite 3-D point.

    Args:
        name: Field name for error messages.
        value: Three coordinates [m].

    Returns:
        Array of shape (3,).
    """
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f'{name}: not a 3-D point: {value!r}') from None
    if arr.shape != (3,):
        raise InputError(f'{name}: expected 3 coordinates, got {arr.size}')
    if not np.all(np.isfinite(arr)):
        raise InputError(f'{name}: not finite: {arr.tolist()}')
    check_coordinates(name, arr)
    return arr


@dataclass(frozen=True)
class Box:
    """Axis-aligned flight box: the whole space the UAV may use.

    Attributes:
        lo: Minimum corner [m].
        hi: Maximum corner [m].
    """

    lo: NDArray
    hi: NDArray

    @classmethod
    def from_corners(cls, lo: ArrayLike, hi: ArrayLike) -> 'Box':
        """Validate and build a box; every side must have positive length."""
        lo_a, hi_a = as_point('bounds.min', lo), as_point('bounds.max', hi)
        if np.any(hi_a <= lo_a):
            axis = 'xyz'[int(np.argmax(hi_a <= lo_a))]
            raise InputError(f'bounds: max.{axis} must exceed min.{axis} '
                             f'(min={lo_a.tolist()}, max={hi_a.tolist()})')
        return cls(lo_a, hi_a)

    @classmethod
    def around(cls, points: NDArray, margin: float = 0.1) -> 'Box':
        """Smallest box holding the points, grown by a fraction of its diagonal."""
        lo, hi = points.min(axis=0), points.max(axis=0)
        pad = max(margin * vector_length(hi - lo), 1.0)
        return cls(lo - pad, hi + pad)

    @cached_property
    def diagonal(self) -> float:
        """Length of the box's diagonal [m]."""
        return vector_length(self.hi - self.lo)

    @cached_property
    def volume(self) -> float:
        """Volume of the box [m^3]."""
        return float(np.prod(self.hi - self.lo))

    def contains(self, point: NDArray, tol: float = 1e-9) -> bool:
        """Return whether the point lies in the box (boundary included)."""
        eps = tol * max(self.diagonal, 1.0)
        return bool(np.all(point >= self.lo - eps) and np.all(point <= self.hi + eps))

    def clip(self, points: NDArray) -> NDArray:
        """Project points onto the box."""
        return np.clip(points, self.lo, self.hi)


@dataclass(frozen=True)
class ThreatField:
    """Known radars: positions and intensities F, with a k-d tree over the positions.

    Attributes:
        positions: Threat positions, shape (N, 3) [m].
        intensities: Transmitter intensities F > 0, shape (N,).
    """

    positions: NDArray
    intensities: NDArray
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def from_arrays(cls, positions: ArrayLike, intensities: ArrayLike) -> 'ThreatField':
        """Validate positions and intensities (finite, F > 0, matching lengths).

        Raises:
            InputError: naming the bad field, index and value.
        """
        pos = _finite_array('threats.position', positions, (3,))
        check_coordinates('threats', pos)
        f = _finite_array('threats.intensity', intensities, ())
        if len(f) != len(pos):
            raise InputError(f'threats: {len(pos)} positions but {len(f)} intensities')
        bad = np.flatnonzero(f <= 0)
        if len(bad):
            raise InputError(f'threats[{int(bad[0])}].intensity: must be > 0, got '
                             f'{float(f[bad[0]])!r} ({len(bad)} such threats)')
        pos.setflags(write=False)
        f.setflags(write=False)
        return cls(pos, f)

    def __len__(self) -> int:
        return len(self.positions)

    @cached_property
    def tree(self) -> cKDTree:
        """k-d tree over the threat positions."""
        # A node's own process (its plans run in a child) reads threats, never their tree.
        from threat_planner.core import _scipy_first  # noqa: F401 (before any scipy)
        from scipy.spatial import cKDTree
        return cKDTree(self.positions)

    def far_field(self, radius: float) -> 'FarField':
        """Return the threats' cells for a cut-off of ``radius`` [m], built once per radius."""
        key = ('far_field', float(radius))
        if key not in self._cache:
            from threat_planner.core.world.far_field import FarField
            self._cache[key] = FarField(self.positions, self.intensities, radius)
        return self._cache[key]

    @cached_property
    def total_intensity(self) -> float:
        """Sum of all intensities F."""
        return float(self.intensities.sum())

    @cached_property
    def median_intensity(self) -> float:
        """Median intensity F (0 without threats)."""
        # Not np.median: its NaN check imports numpy.ma (12 ms of a process's first plan).
        f = np.sort(self.intensities)
        return float((f[(len(f) - 1) // 2] + f[len(f) // 2]) / 2) if len(f) else 0.0

    def received_power(self, points: ArrayLike, q: float = 1.0) -> NDArray:
        """Radar power received from a target at each point, sum_i Q F_i / R_i^4 (eq. 3).

        Args:
            points: Query points, shape (m, 3) [m].
            q: The radar constant Q of eq. 2.

        Returns:
            Array (m,) of powers (inf on a threat).
        """
        pts = np.atleast_2d(np.asarray(points, float))
        if len(self) == 0:
            return np.zeros(len(pts))
        d2 = np.sum((pts[:, None, :] - self.positions[None]) ** 2, axis=2)
        with np.errstate(divide='ignore'):
            return q * (self.intensities[None] / d2 ** 2).sum(axis=1)

    def typical_spacing(self, box: Box) -> float:
        """Mean spacing of the threats if spread evenly through the box [m]."""
        return (box.volume / max(len(self), 1)) ** (1.0 / 3.0)

    def near_pairs(self, a: NDArray, b: NDArray, radius: float
                   ) -> tuple[NDArray, NDArray, NDArray]:
        """Threats within ``radius`` of each segment, for the cut-off cost.

        Every threat closer than ``radius`` to a segment is in the result (the query is a
        ball of radius + L/2 about the segment's midpoint, a superset), so a dropped threat
        is at least ``radius`` from every point of the segment and adds at most
        F_i * L / radius^4 to it: the returned bound sums that over the dropped threats.

        Args:
            a: Segment starts, shape (S, 3) [m].
            b: Segment ends, shape (S, 3) [m].
            radius: Cut-off distance [m].

        Returns:
            ``(segment_index, threat_index, bound)``, bound of shape (S,) being the most the
            dropped threats can add to each segment's J_R.
        """
        mid = 0.5 * (a + b)
        length = np.linalg.norm(b - a, axis=1)
        reach = radius + 0.5 * length
        # Per-segment reach: a single query at the largest reach would hand long edges'
        # neighbourhoods to every short one.
        lists = self.tree.query_ball_point(mid, reach, return_sorted=False)
        counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
        seg = np.repeat(np.arange(len(a), dtype=np.int64), counts)
        thr = np.fromiter(chain.from_iterable(lists), dtype=np.int64, count=int(counts.sum()))
        near_f = np.bincount(seg, self.intensities[thr], len(a))
        bound = np.maximum(self.total_intensity - near_f, 0.0) * length / radius ** 4
        return seg, thr, bound


def check_endpoints(start: ArrayLike, goal: ArrayLike, box: Box,
                    threats: ThreatField) -> tuple[NDArray, NDArray]:
    """Validate start and goal: finite, inside the box, not on a threat.

    Raises:
        InputError: naming the point and the problem.
    """
    out = []
    for name, value in (('start', start), ('goal', goal)):
        p = as_point(name, value)
        if not box.contains(p):
            raise InputError(f'{name}: {p.tolist()} is outside bounds '
                             f'{box.lo.tolist()}..{box.hi.tolist()}')
        if len(threats):
            # Not threats.tree: a node's process checks every input it takes, and building
            # a k-d tree (and importing scipy.spatial) for one query costs more than this.
            diff = threats.positions - p
            d2 = np.einsum('ij,ij->i', diff, diff)
            i = int(np.argmin(d2))
            d = math.sqrt(d2[i])
            if d <= 1e-9 * max(box.diagonal, 1.0):
                raise InputError(f'{name}: {p.tolist()} is on threat {i}')
        out.append(p)
    return out[0], out[1]
