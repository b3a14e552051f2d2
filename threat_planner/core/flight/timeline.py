"""The threat picture in time: each threat a sequence of straight-line pieces.

A piece is one threat flying at constant velocity over a time window ``[t_on, t_off)``:
position ``q(t) = origin + velocity * (t - t_on)``. A threat that appears (pops up) starts
a piece, one that is moved or changes velocity ends its piece and starts the next, one that
is removed ends its piece. Threat indices are the scenario's threats first, then the added
ones in the order they were added.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError

__all__ = ['Snapshot', 'ThreatTimeline']


@dataclass(frozen=True)
class Snapshot:
    """The threats active at one time, at their positions then.

    Attributes
    ----------
    field : ThreatField
        Positions [m] and intensities of the active threats.
    velocities : NDArray
        Their velocities (N, 3) [m/s].
    lethal : NDArray
        Their lethal radii (N,) [m], NaN for none.
    ids : NDArray
        Their threat indices (N,).

    """

    field: ThreatField
    velocities: NDArray
    lethal: NDArray
    ids: NDArray


class ThreatTimeline:
    """Threats as straight-line pieces in time (module docstring).

    Parameters
    ----------
    field : ThreatField
        The threats known at ``t0``.
    velocities : array_like, optional
        Their velocities (N, 3) [m/s]; zeros if None.
    lethal : array_like, optional
        Their lethal radii (N,) [m], NaN for none.
    t0 : float
        Time the positions hold at [s].

    """

    def __init__(self, field: ThreatField, velocities: ArrayLike | None = None,
                 lethal: ArrayLike | None = None, t0: float = 0.0) -> None:
        n = len(field)
        vel = np.zeros((n, 3)) if velocities is None else np.asarray(velocities, float)
        if vel.shape != (n, 3) or not np.all(np.isfinite(vel)):
            raise InputError(f'threats.velocity: expected {n} finite [vx, vy, vz], got shape '
                             f'{list(vel.shape)}')
        leth = np.full(n, np.nan) if lethal is None else np.asarray(lethal, float)
        self._ids = list(range(n))
        self._f = list(field.intensities.astype(float))
        self._origin = [p for p in field.positions.astype(float)]
        self._vel = [v for v in vel]
        self._on = [float(t0)] * n
        self._off = [np.inf] * n
        self._lethal = list(leth)
        self._open = {i: i for i in range(n)}   # threat index -> its current piece
        self.n_threats = n
        self._arrays: tuple | None = None

    # -- changes -----------------------------------------------------------------------
    def add(self, t: float, position: ArrayLike, intensity: float, velocity: ArrayLike = (0, 0, 0),
            lethal_radius: float = np.nan) -> int:
        """Start a new threat at time `t` [s]; return its index."""
        index = self.n_threats
        self.n_threats += 1
        self._start(index, t, np.asarray(position, float), float(intensity),
                    np.asarray(velocity, float), float(lethal_radius))
        return index

    def move(self, t: float, index: int, position: ArrayLike | None = None,
             velocity: ArrayLike | None = None) -> None:
        """Move threat `index` from time `t` [s].

        It continues from `position` (default: where it is) with `velocity` (default:
        its velocity so far).
        """
        piece = self._current(index, 'move_threat')
        here = self._at(piece, t)
        self._off[piece] = float(t)
        self._start(index, t, here if position is None else np.asarray(position, float),
                    self._f[piece],
                    self._vel[piece] if velocity is None else np.asarray(velocity, float),
                    self._lethal[piece])

    def remove(self, t: float, index: int) -> None:
        """End threat `index` at time `t` [s]."""
        piece = self._current(index, 'remove_threat')
        self._off[piece] = float(t)
        del self._open[index]
        self._arrays = None

    def _current(self, index: int, what: str) -> int:
        if index not in self._open:
            state = 'was removed' if 0 <= index < self.n_threats else 'does not exist'
            raise InputError(f'{what}.index: threat {index} {state} '
                             f'({self.n_threats} threats so far)')
        return self._open[index]

    def _start(self, index: int, t: float, position: NDArray, intensity: float,
               velocity: NDArray, lethal: float) -> None:
        self._ids.append(index)
        self._f.append(intensity)
        self._origin.append(position)
        self._vel.append(velocity)
        self._on.append(float(t))
        self._off.append(np.inf)
        self._lethal.append(lethal)
        self._open[index] = len(self._ids) - 1
        self._arrays = None

    def _at(self, piece: int, t: float) -> NDArray:
        return self._origin[piece] + self._vel[piece] * (t - self._on[piece])

    # -- views ---------------------------------------------------------------------------
    def pieces(self) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
        """Return ``(ids, intensity, origin, velocity, t_on, t_off, lethal)`` as arrays."""
        if self._arrays is None:
            self._arrays = (np.asarray(self._ids, np.int64), np.asarray(self._f, float),
                            np.asarray(self._origin, float).reshape(-1, 3),
                            np.asarray(self._vel, float).reshape(-1, 3),
                            np.asarray(self._on, float), np.asarray(self._off, float),
                            np.asarray(self._lethal, float))
        return self._arrays

    def active(self, t: float) -> NDArray:
        """Return the indices of the pieces active at time `t` [s]."""
        _, _, _, _, on, off, _ = self.pieces()
        return np.flatnonzero((on <= t) & (t < off))

    def snapshot(self, t: float) -> Snapshot:
        """Return the threats active at time `t` [s], where they are then."""
        ids, f, origin, vel, on, _, lethal = self.pieces()
        k = self.active(t)
        pos = origin[k] + vel[k] * (t - on[k])[:, None]
        return Snapshot(ThreatField.from_arrays(pos.reshape(-1, 3), f[k]), vel[k], lethal[k],
                        ids[k])

    def moving(self) -> bool:
        """Whether any piece moves or starts or ends at a finite time after another."""
        _, _, _, vel, on, off, _ = self.pieces()
        return bool(np.any(vel != 0) or np.any(np.isfinite(off))
                    or (len(on) > 0 and np.ptp(on) > 0))
