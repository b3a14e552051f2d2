"""Compiled (numba) rounds of the augmented Lagrangian: L-BFGS runs and multiplier updates.

:meth:`threat_planner.core.optimise.optimisation._Level.constrained` ran its rounds in Python: per
round one L-BFGS call, the constraint values, the multiplier update and a limit check, each
a few microseconds of interpreter and call overhead (a 3-round slope-held screening call
at 8 segments spent 180 us in Python around 640 us of compiled work). Here one call runs
them all (``bench/results/profile_rounds_{before,after}.txt``: 209,507 -> 168,973 Python
calls over 30 plans, 19.8 -> 18.0 ms per profiled plan). Under a cut-off the near threats
are those of where the pairs were picked, so the call returns as soon as the path has moved
far enough from there for the caller to pick them again, and is called once more with the
state it left.
"""

from __future__ import annotations

import math

import numpy as np

from threat_planner.core.cost.kernels import njit, parallel_guard
from threat_planner.core.optimise.lbfgs import _minimise
from threat_planner.core.optimise.limit_kernels import _measure, _values
from threat_planner.core.optimise.limits import CHECK_SLACK

__all__ = ['STATE', 'counters', 'has_best', 'new_state', 'run_rounds']

#: Slots of the state array: next round, penalty, last violation, last objective, least
#: feasible J (inf: none yet), L-BFGS iterations, evaluations and runs so far.
STATE = ('round', 'mu', 'violation', 'f', 'best_j', 'iterations', 'evaluations', 'runs')
_ROUND, _MU, _VIOLATION, _F, _BEST_J, _NIT, _NFEV, _RUNS = range(len(STATE))


def new_state(mu: float, best_j: float = math.inf) -> np.ndarray:
    """Return the state of rounds about to start at penalty mu (best_j: a start's J)."""
    state = np.zeros(len(STATE))
    state[_MU], state[_VIOLATION], state[_F], state[_BEST_J] = mu, math.inf, math.inf, best_j
    return state


def counters(state: np.ndarray) -> tuple[int, int, int]:
    """Return the L-BFGS iterations, evaluations and runs the rounds made."""
    return int(state[_NIT]), int(state[_NFEV]), int(state[_RUNS])


def has_best(state: np.ndarray) -> bool:
    """Whether the rounds (or the start) hold a feasible answer."""
    return bool(np.isfinite(state[_BEST_J]))


@njit(cache=True)
def _meets(points, floor_z, limits):
    """Whether a path meets ``limits`` = (climb, dive [deg], radius, altitude [m]).

    The comparisons of :func:`threat_planner.core.optimise.limits.check_limits`, in the same
    floating-point operations.
    """
    climb, dive, radius, alt = _measure(points, floor_z)
    if climb > limits[0] + CHECK_SLACK or dive > limits[1] + CHECK_SLACK:
        return False
    if radius < limits[2] * (1.0 - CHECK_SLACK):
        return False
    return not alt < limits[3] - CHECK_SLACK * max(limits[3], 1.0)


#: A segment shorter than this fraction of the mean segment is a vertex folded onto its
#: neighbour: the turn rows' gradients grow as 1 / length there and L-BFGS stalls (n20
#: seed 1 w 0.8 of the random fields, one threat moved 1 nm: a vertex 1.5e-5 m from the
#: start, six rounds at one J and violation, the plan 4.2x the unmoved one's).
FOLDED = 1e-3


@njit(cache=True)
def _unfold(x, fraction):
    """Move each vertex folded onto a neighbour to the middle of its neighbours (in place).

    Where a vertex sits on its neighbour the polyline through both is the straight segment
    on to the next vertex, so the middle of that segment leaves the path's shape (and J)
    as it was to within the fold's length, and a convex combination stays in the bounds.
    Returns the vertices moved.
    """
    n1 = x.shape[0] // 3
    if n1 < 3:
        return 0
    total = 0.0
    for s in range(n1 - 1):
        total += math.sqrt((x[3 * s + 3] - x[3 * s]) ** 2 + (x[3 * s + 4] - x[3 * s + 1]) ** 2
                           + (x[3 * s + 5] - x[3 * s + 2]) ** 2)
    tiny = fraction * total / (n1 - 1)
    moved = 0
    for s in range(n1 - 1):
        length = math.sqrt((x[3 * s + 3] - x[3 * s]) ** 2 + (x[3 * s + 4] - x[3 * s + 1]) ** 2
                           + (x[3 * s + 5] - x[3 * s + 2]) ** 2)
        if length >= tiny:
            continue
        i = s + 1 if s + 1 < n1 - 1 else s
        for d in range(3):
            x[3 * i + d] = 0.5 * (x[3 * i - 3 + d] + x[3 * i + 3 + d])
        moved += 1
    return moved


@njit(cache=True)
def _rounds(x, lo, hi, positions, f, w, seg, thr, c2, c3, spring, even, scale, lim, lam,
            maxiter, ftol, gtol, m, max_step, pre, rounds, gain, growth, tolerance, limits,
            floor_z, picked, repick, best_x, state, trace):
    """Augmented Lagrangian rounds from x (in place), as ``_Level.constrained`` states them.

    Returns 0 when the rounds ended, 1 when the path moved ``repick`` [m] from ``picked``
    before a round (the caller picks the pairs again and calls on). ``trace`` (rounds, 3)
    receives each round's J, feasibility and violation.
    """
    nv = x.shape[0]
    n1 = nv // 3
    out = np.empty(nv)
    parts = np.zeros(2)
    c = np.zeros(lam.shape[0])
    gbuf = np.zeros(lam.shape[0])
    pgrad = np.zeros((n1, 3))
    while state[_ROUND] < rounds:
        if repick < math.inf:
            far = 0.0
            for k in range(0, nv, 3):
                far = max(far, (x[k] - picked[k]) ** 2 + (x[k + 1] - picked[k + 1]) ** 2
                          + (x[k + 2] - picked[k + 2]) ** 2)
            if math.sqrt(far) >= repick:
                return 1
        mu = state[_MU]
        _, nit, nfev, _ = _minimise(x, lo, hi, positions, f, w, seg, thr, c2, c3, spring,
                                    even, scale, lim, lam, mu, gbuf, pgrad, maxiter, ftol,
                                    gtol, m, max_step, pre, math.inf, out, parts)
        x[:] = out
        state[_NIT] += nit
        state[_NFEV] += nfev
        state[_RUNS] += 1
        p = x.reshape((n1, 3))
        _values(p, lim[0], lim[1], lim[2], lim[3] > 0.0, lim[4] > 0.0, lim[5] > 0.0, c)
        violation = 0.0
        for k in range(c.shape[0]):
            violation = max(violation, -c[k])
            lam[k] = max(0.0, lam[k] - mu * c[k])
        j = parts[0]
        fv = parts[1] / scale
        feasible = _meets(p, floor_z, limits)
        r = int(state[_ROUND])
        trace[r, 0] = j
        trace[r, 1] = 1.0 if feasible else 0.0
        trace[r, 2] = violation
        state[_ROUND] += 1
        if not feasible and r > 0 and abs(j - trace[r - 1, 0]) <= 1e-9 * abs(j):
            # The round did not move: a folded vertex may hold it (FOLDED).
            _unfold(x, FOLDED)
        if feasible:
            # A feasible round that gained little over the last one ends the level.
            stop = gain >= 0.0 and state[_BEST_J] < math.inf and (
                state[_BEST_J] - j < gain * abs(j))
            if j < state[_BEST_J]:
                state[_BEST_J] = j
                best_x[:] = x
            if stop or abs(state[_F] - fv) <= tolerance * max(abs(fv), 1.0):
                return 0
        if violation > 0.25 * state[_VIOLATION]:
            state[_MU] = mu * growth
        state[_VIOLATION] = violation
        state[_F] = fv
    return 0


def run_rounds(x, lo, hi, positions, f, w, pairs, c2, c3, spring, even, scale, lim, lam,
               maxiter, ftol, max_step, pre, rounds, gain, growth, tolerance, limits,
               floor_z, picked, repick, best_x, state, trace, gtol=1e-7, memory=20):
    """Run :func:`_rounds` (``pairs`` as in :func:`.lbfgs.minimise`; ``gain`` < 0 for none).

    ``x``, ``lam``, ``best_x``, ``state`` and ``trace`` are updated in place.
    """
    with parallel_guard(len(pairs[0]) or (len(x) // 3 - 1) * len(positions)):
        return int(_rounds(x, lo, hi, positions, f, float(w), pairs[0], pairs[1], c2, c3,
                           float(spring), float(even), float(scale), lim, lam, int(maxiter),
                           float(ftol), float(gtol), int(memory), float(max_step), bool(pre),
                           int(rounds), float(gain), float(growth), float(tolerance),
                           limits, float(floor_z), picked, float(repick), best_x, state,
                           trace))
