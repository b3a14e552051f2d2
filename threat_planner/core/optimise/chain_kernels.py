"""Compiled (numba) chain kernels: the mass-spring integration and equal-step resampling.

:func:`.smoothing.smooth` integrates the paper's chain (eq. 4-14) for up
to 4,000 steps a route, and ``paper`` and ``improved`` smooth dozens of routes a plan (the
k sweep): in numpy a step of a 21-mass chain among 20 threats cost ~130 us, nearly all
call overhead, so ``threat-planner paper`` spent 54 of its 58 s integrating. Here a whole
integration is one call, the arithmetic of the numpy version
(:func:`~threat_planner.core.optimise.smoothing.chain_forces` and the step of ``smooth``) but for
the last bit: d^5 is d2^2 sqrt(d2) (a ``pow`` a pair was half the integration's time) and
sums run in loop order (numpy's ``einsum`` orders some differently). Tests check the forces
against chain_forces to 1e-12 and 200 steps against the numpy integration to 1e-7 m.
On the 21 bundled cases (``bench/results/paper_methods.md``) the median plan went 53.8 ->
4.2 ms (``paper``, the same J to 9 digits) and 3.2 s -> 113 ms (``improved``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.kernels import njit

__all__ = ['integrate', 'resample']


@njit(cache=True)
def _forces(x, v, positions, f, k, b, q, rest_length, out):
    """Net force on every mass into out, as chain_forces computes it (eq. 7-13)."""
    n1 = x.shape[0]
    out[:, :] = 0.0
    for s in range(n1 - 1):
        dx = x[s + 1, 0] - x[s, 0]
        dy = x[s + 1, 1] - x[s, 1]
        dz = x[s + 1, 2] - x[s, 2]
        dd = math.sqrt(dx * dx + dy * dy + dz * dz)
        den = dd if dd > 0 else 1.0
        nx, ny, nz = dx / den, dy / den, dz / den
        tension = k * max(dd - rest_length, 0.0)
        dv = ((v[s + 1, 0] - v[s, 0]) * nx + (v[s + 1, 1] - v[s, 1]) * ny
              + (v[s + 1, 2] - v[s, 2]) * nz)
        pull = tension + b * dv
        out[s, 0] += pull * nx
        out[s, 1] += pull * ny
        out[s, 2] += pull * nz
        out[s + 1, 0] -= pull * nx
        out[s + 1, 1] -= pull * ny
        out[s + 1, 2] -= pull * nz
    if positions.shape[0] == 0:
        return
    for j in range(n1):
        ax = ay = az = 0.0
        for i in range(positions.shape[0]):
            rx = x[j, 0] - positions[i, 0]
            ry = x[j, 1] - positions[i, 1]
            rz = x[j, 2] - positions[i, 2]
            d2 = rx * rx + ry * ry + rz * rz
            # d^5 as d2^2 sqrt(d2): a pow a pair cost half the integration.
            d5 = d2 * d2 * math.sqrt(d2)
            # numpy's nan_to_num(posinf=0) of Q F / d^5 (Q >= 0, F > 0): a mass on a threat,
            # or so near that d^5 underflows or the push overflows, feels none from it.
            mag = q * f[i] / d5 if d5 > 0 else 0.0
            if mag == math.inf:
                mag = 0.0
            ax += mag * rx
            ay += mag * ry
            az += mag * rz
        out[j, 0] += ax
        out[j, 1] += ay
        out[j, 2] += az


@njit(cache=True)
def _integrate(x, positions, f, k, b, q, rest_length, mass, dt, drag, max_move, still,
               max_steps, lo, hi, walls):
    """Semi-implicit Euler steps of ``smooth`` on x in place; (steps, converged)."""
    n1 = x.shape[0]
    v = np.zeros_like(x)
    force = np.empty_like(x)
    move = np.empty_like(x)
    calm = 0
    for step in range(1, max_steps + 1):
        _forces(x, v, positions, f, k, b, q, rest_length, force)
        for j in range(1, n1 - 1):
            for c in range(3):
                v[j, c] += dt * (force[j, c] - drag * v[j, c]) / mass
        moved = 0.0
        for j in range(n1):
            mx, my, mz = dt * v[j, 0], dt * v[j, 1], dt * v[j, 2]
            size = math.sqrt(mx * mx + my * my + mz * mz)
            if size > max_move:
                scale = max_move / size
                mx, my, mz = mx * scale, my * scale, mz * scale
                v[j, 0], v[j, 1], v[j, 2] = mx / dt, my / dt, mz / dt
            move[j, 0], move[j, 1], move[j, 2] = mx, my, mz
        for j in range(n1):
            for c in range(3):
                before = x[j, c]
                now = before + move[j, c] if 0 < j < n1 - 1 else before
                if walls:
                    # np.clip(x, lo, hi): minimum(maximum(x, lo), hi).
                    clipped = min(max(now, lo[c]), hi[c])
                    if clipped != now:
                        v[j, c] = 0.0
                    now = clipped
                x[j, c] = now
                moved = max(moved, abs(now - before))
        calm = calm + 1 if moved < still else 0
        if calm >= 10:
            return step, True
    return max_steps, False


def integrate(points: NDArray, positions: NDArray, intensities: NDArray, k: float,
              damping: float, mass: float, q: float, rest_length: float, dt: float,
              drag: float, max_move: float, still: float, max_steps: int,
              bounds: tuple[NDArray, NDArray] | None) -> tuple[NDArray, int, bool]:
    """Run ``smooth``'s integration from points; ``(resting chain, steps, converged)``.

    ``dt`` [s], ``drag``, ``max_move`` [m] and ``still`` [m] (the move below which a step
    counts as calm) are ``smooth``'s; ``bounds`` its walls or None.
    """
    x = np.array(points, float)
    walls = bounds is not None
    lo = np.asarray(bounds[0], float) if walls else np.zeros(3)
    hi = np.asarray(bounds[1], float) if walls else np.zeros(3)
    steps, converged = _integrate(
        x, np.ascontiguousarray(positions, float).reshape(-1, 3),
        np.ascontiguousarray(intensities, float), float(k), float(damping), float(q),
        float(rest_length), float(mass), float(dt), float(drag), float(max_move),
        float(still), int(max_steps), np.ascontiguousarray(lo), np.ascontiguousarray(hi),
        walls)
    return x, int(steps), bool(converged)


@njit(cache=True)
def _resample(points, n_segments, out):
    """Points at equal arc-length steps along a polyline into out (n+1, 3), ends kept."""
    m = points.shape[0]
    cum = np.zeros(m)
    for k in range(1, m):
        d = points[k] - points[k - 1]
        cum[k] = cum[k - 1] + math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    total = cum[m - 1]
    j = 0
    for q in range(n_segments + 1):
        arc = total * q / n_segments
        # The last segment that starts at or before arc (zero-length ones passed over).
        while j < m - 2 and cum[j + 1] <= arc:
            j += 1
        span = cum[j + 1] - cum[j]
        a = (arc - cum[j]) / span if span > 0 else 0.0
        a = min(max(a, 0.0), 1.0)
        out[q] = points[j] + a * (points[j + 1] - points[j])
    out[0] = points[0]
    out[n_segments] = points[m - 1]


def resample(points: NDArray, n_segments: int) -> NDArray:
    """Points at equal arc-length steps along a polyline (n+1, 3), ends kept, compiled."""
    points = np.ascontiguousarray(points, float)
    out = np.empty((n_segments + 1, 3))
    if len(points) == 1 or n_segments < 1:
        out[:] = points[0]
        out[-1] = points[-1]
        return out
    _resample(points, int(n_segments), out)
    return out
