"""Artificial-potential-field smoothing (paper Section 3.4, eq. 4-14) and the angle checks.

The initial path becomes a chain of n+1 masses joined by springs that pull and never push
(rubber bands), with linear damping between neighbours (eq. 9-10) and repulsion
Q F_i / d^4 from each threat along the threat-to-mass direction (eq. 13). The chain is
integrated until it comes to rest; the resting chain is the smoothed path. Then each
segment's pitch angle and each point's turn angle are checked against the UAV's limits.

Beyond the paper: a light absolute drag is added to the paper's relative damping, because
relative damping alone leaves the chain's slowest mode ringing for thousands of steps; the
rest state (force balance) is the same with or without it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from threat_planner.core._vector import vector_length
from threat_planner.core.optimise import chain_kernels


@dataclass(frozen=True)
class SmoothingResult:
    """Outcome of the mass-spring integration.

    Attributes:
        points: Resting chain, (n+1, 3) [m].
        steps: Integration steps taken.
        converged: Whether the stopping rule was met before the step limit.
    """

    points: NDArray
    steps: int
    converged: bool


@dataclass(frozen=True)
class AngleCheck:
    """Pitch and turn angles of a path against the UAV's limits.

    Attributes:
        max_pitch_deg: Largest segment pitch |atan(dz / horizontal)| [deg].
        max_turn_deg: Largest turn between consecutive segments [deg].
        pitch_ok: Every segment within the pitch limit.
        turn_ok: Every interior point within the turn limit.
    """

    max_pitch_deg: float
    max_turn_deg: float
    pitch_ok: bool
    turn_ok: bool

    @property
    def feasible(self) -> bool:
        """Both limits are met."""
        return self.pitch_ok and self.turn_ok


def resample(points: NDArray, n_segments: int) -> NDArray:
    """Points at equal arc-length steps along a polyline, ends kept.

    Args:
        points: Polyline, (m, 3) [m].
        n_segments: Number of equal segments n; the result has n+1 points.

    Returns:
        Array (n+1, 3) [m].
    """
    # Compiled: the optimiser's levels and the screening resample ~40 times a plan.
    return chain_kernels.resample(points, n_segments)


def pitch_angles(points: NDArray) -> NDArray:
    """Pitch of each segment, atan(dz / horizontal distance) [deg], (n,)."""
    d = np.diff(points, axis=0)
    return np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))


def turn_angles(points: NDArray) -> NDArray:
    """Turn (steering) angle at each interior point between its two segments [deg], (n-1,).

    Zero-length segments are skipped over: the angle is taken between the nearest
    non-degenerate segments on either side.
    """
    d = np.diff(points, axis=0)
    norm = np.linalg.norm(d, axis=1)
    keep = norm > 1e-12 * max(float(norm.max(initial=0.0)), 1.0)
    u = d[keep] / norm[keep, None]
    if len(u) < 2:
        return np.zeros(0)
    cosang = np.clip(np.einsum('ik,ik->i', u[:-1], u[1:]), -1.0, 1.0)
    return np.degrees(np.arccos(cosang))


def check_angles(points: NDArray, max_pitch_deg: float, max_turn_deg: float) -> AngleCheck:
    """Check pitch and turn angles against limits (the paper's last step of Section 3.4).

    Args:
        points: Path, (n+1, 3) [m].
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn limit [deg].

    Returns:
        The AngleCheck.
    """
    pitch = float(np.max(np.abs(pitch_angles(points)), initial=0.0))
    turn = float(np.max(turn_angles(points), initial=0.0))
    # A hair of slack so that a path optimised onto the limit is not failed by rounding.
    return AngleCheck(pitch, turn, pitch <= max_pitch_deg + 1e-6, turn <= max_turn_deg + 1e-6)


def chain_forces(x: NDArray, v: NDArray, positions: NDArray, intensities: NDArray,
                 k: float, b: float, q: float, rest_length: float) -> NDArray:
    """Net force on every mass (eq. 7-14); the two end masses are held by the caller.

    Args:
        x: Mass positions, (n+1, 3) [m].
        v: Mass velocities, (n+1, 3) [m/s].
        positions: Threat positions, (N, 3) [m].
        intensities: Threat intensities F, (N,).
        k: Spring coefficient.
        b: Damping coefficient between neighbours.
        q: Repulsion constant Q of eq. 13.
        rest_length: Spring rest length [m]; springs shorter than it exert no force.

    Returns:
        Forces, (n+1, 3).
    """
    d = np.diff(x, axis=0)
    dd = np.linalg.norm(d, axis=1)                                       # eq. 4
    n = d / np.where(dd > 0, dd, 1.0)[:, None]                           # eq. 5-6
    tension = k * np.maximum(dd - rest_length, 0.0)                      # eq. 7-8, pull only
    dv = np.einsum('jk,jk->j', v[1:] - v[:-1], n)
    damp = b * dv                                                        # eq. 9-10
    pull = (tension + damp)[:, None] * n
    force = np.zeros_like(x)
    force[:-1] += pull
    force[1:] -= pull
    if len(positions):
        r = x[:, None, :] - positions[None, :, :]                        # eq. 11-12
        d2 = np.einsum('jik,jik->ji', r, r)
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
            mag = q * intensities[None, :] / d2 ** 2.5                   # Q F / d^4 / d
        force += np.einsum('ji,jik->jk', np.nan_to_num(mag, posinf=0.0), r)   # eq. 13
    return force


def smooth(points: NDArray, positions: NDArray, intensities: NDArray, k: float,
           damping: float, mass: float, q: float, rest_length: float = 0.0,
           max_steps: int = 4000, tolerance: float = 1e-4,
           bounds: tuple[NDArray, NDArray] | None = None) -> SmoothingResult:
    """Integrate the mass-spring chain to rest (eq. 14).

    Integration is semi-implicit Euler with step dt = 0.5 sqrt(M/k), stable for the springs;
    a mass moves at most a quarter of the mean spacing per step, so that a steep threat
    force cannot throw it across a radar. Stopping rule: the largest move in one step stays
    below ``tolerance`` times the mean spacing for 10 steps in a row.

    Args:
        points: Initial chain, (n+1, 3) [m]; ends are fixed.
        positions: Threat positions, (N, 3) [m].
        intensities: Threat intensities F, (N,).
        k: Spring coefficient.
        damping: Damping coefficient b between neighbours (eq. 9-10).
        mass: Mass M of each point.
        q: Repulsion constant Q (eq. 13).
        rest_length: Spring rest length [m].
        max_steps: Step limit.
        tolerance: Relative move that counts as at rest.
        bounds: ``(lo, hi)`` walls the masses stay within at every step [m], or None.

    Returns:
        The SmoothingResult.
    """
    x = np.array(points, float)
    if len(x) < 3:
        return SmoothingResult(x, 0, True)
    n = len(x) - 1
    dt = 0.5 * np.sqrt(mass / k)
    # Drag near critical for the slowest chain mode (omega = 2 sqrt(k/M) sin(pi / 2n)).
    drag = 2.0 * mass * 2.0 * np.sqrt(k / mass) * np.sin(np.pi / (2 * n))
    spacing = vector_length(x[-1] - x[0]) / n
    spacing = max(spacing, float(np.linalg.norm(np.diff(x, axis=0), axis=1).mean()), 1e-9)
    # Compiled (chain_kernels): every step in one call, the forces as chain_forces'.
    x, steps, converged = chain_kernels.integrate(
        x, positions, intensities, k, damping, mass, q, rest_length, dt, drag,
        0.25 * spacing, tolerance * spacing, max_steps, bounds)
    return SmoothingResult(x, steps, converged)
