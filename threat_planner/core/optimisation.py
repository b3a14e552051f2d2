"""Direct minimisation of J (beyond the paper) inside the box and the flight limits.

The smoothed chain balances springs against repulsion, which is not the same as least J.
Here the interior vertices move to minimise J itself with its exact gradient (the compiled
kernel of :mod:`.kernels`), inside the flight box (bounds, raised by the minimum altitude).
Where the result breaks a flight limit (:mod:`.limits`), an augmented Lagrangian takes
over: L-BFGS-B, bounds native, on J plus the Powell-Hestenes-Rockafellar term of the limit
constraints, the multipliers updated between runs. It replaced SLSQP (measured in
``bench/results/profile_*.txt``: SLSQP's dense QP was 70 % of a 20-threat plan). A faint
spring term keeps vertices evenly spread, because J alone does not care where along the
path they sit, and bunched vertices turn on tiny circles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from threat_planner.core.kernels import cost_gradient
from threat_planner.core.limit_kernels import LimitTerm
from threat_planner.core.limits import check_limits, FlightLimits
from threat_planner.core.smoothing import resample
from threat_planner.core.threats import Box, ThreatField

__all__ = ['OptimisationResult', 'minimise_cost']

#: Weight of the even-spacing term relative to the length cost.
SPACING_WEIGHT = 1e-3
#: Weight of the even-spacing (length variance) term under the flight limits, where
#: bunched vertices make the constraints stiff (their gradients grow as 1 / length) and
#: the penalty would otherwise fold the path into near-zero segments.
EVEN_SPACING_WEIGHT = 1.0
#: Most pair re-picks of a cut-off minimisation.
MAX_PAIR_ROUNDS = 6
#: The optimiser aims this far inside the angle limits [deg] ...
ANGLE_MARGIN_DEG = 0.05
#: ... and this fraction above the minimum turn radius, so the exact check passes.
RADIUS_MARGIN = 2e-3
#: Augmented Lagrangian: first penalty, its growth when the violation stalls, most rounds.
PENALTY_START = 10.0
PENALTY_GROWTH = 10.0
MAX_OUTER = 6
#: Stop the outer rounds once feasible and J (scaled) changed by less than this.
OUTER_TOLERANCE = 1e-5


@dataclass(frozen=True)
class OptimisationResult:
    """Outcome of the direct J minimisation.

    Attributes
    ----------
    points : ndarray
        Optimised path, (n+1, 3) [m].
    iterations : int
        L-BFGS-B iterations over all rounds.
    evaluations : int
        Cost-and-gradient evaluations.
    rounds : int
        L-BFGS-B runs: 1 without binding limits, more for the augmented Lagrangian.
    constrained : bool
        The flight limits bound: the augmented Lagrangian ran.

    """

    points: NDArray
    iterations: int
    evaluations: int
    rounds: int
    constrained: bool = False


def minimise_cost(points: NDArray, threats: ThreatField, w: float, box: Box | None,
                  limits: FlightLimits | None = None, cutoff: float | None = None,
                  max_iterations: int = 1000, tolerance: float = 1e-6,
                  constrained_iterations: int = 200,
                  constrained_only: bool = False) -> OptimisationResult:
    """Minimise J over the interior vertices within the box and the flight limits.

    Parameters
    ----------
    points : ndarray
        Starting path, (n+1, 3) [m]; the ends stay fixed.
    threats : ThreatField
        The threat field.
    w : float
        Threat weight, 0 < w < 1.
    box : Box or None
        Flight box (bounds for every vertex), or None for no bounds.
    limits : FlightLimits, optional
        Flight limits; None or all off for J within the box alone.
    cutoff : float, optional
        If set, count only threats within this distance of each segment [m]; the pairs
        are re-picked whenever the path has moved a quarter of it.
    max_iterations : int
        L-BFGS-B iteration limit of the unconstrained run.
    tolerance : float
        Stop when an iteration lowers J by less than this fraction; 1e-6 put J within
        0.05 % of the yardstick on the bundled scenarios at a tenth of the iterations full
        convergence takes.
    constrained_iterations : int
        L-BFGS-B iteration limit of each augmented Lagrangian round.
    constrained_only : bool
        Skip the box-only run when the start meets the limits (a warm start near the
        constrained optimum: the box-only run would leave it and the rounds come back).

    Returns
    -------
    OptimisationResult

    """
    limits = limits or FlightLimits()
    x = np.array(points, float)
    n = len(x)
    if n < 3:
        return OptimisationResult(x, 0, 0, 0)
    j_l0 = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum()) or 1.0
    spring_unit = (1.0 - w) * (n - 1) / j_l0
    bounds = None
    floor = -np.inf if box is None else float(box.lo[2])
    if box is not None:
        lo = box.lo.copy()
        lo[2] = min(lo[2] + limits.min_altitude_m, box.hi[2])
        bounds = [(a, b) for _ in range(n - 2) for a, b in zip(lo, box.hi)]
        x[1:-1] = np.clip(x[1:-1], lo, box.hi)
    ends = (x[0].copy(), x[-1].copy())
    state = {'pairs': None, 'scale': None, 'spring': SPACING_WEIGHT * spring_unit,
             'even': 0.0}
    positions, intensities = threats.positions, threats.intensities

    def pick_pairs(p: NDArray) -> None:
        if cutoff is not None:
            seg, thr, _ = threats.near_pairs(p[:-1], p[1:], cutoff)
            state['pairs'] = (seg, thr)

    def full(z: NDArray) -> NDArray:
        return np.vstack([ends[0], z.reshape(-1, 3), ends[1]])

    def objective(z: NDArray) -> tuple[float, NDArray]:
        p = full(z)
        j, g = cost_gradient(p, positions, intensities, w, state['pairs'])
        d = np.diff(p, axis=0)
        spring = state['spring']
        j += spring * float(np.sum(d * d))
        g[:-1] -= 2.0 * spring * d
        g[1:] += 2.0 * spring * d
        even = state['even']
        if even > 0.0:
            # m Var(segment length) = sum l^2 - (sum l)^2 / m: spreads the vertices evenly
            # without the pull towards a shorter path a plain spring has.
            ln = np.sqrt(np.einsum('ik,ik->i', d, d))
            mean = float(ln.sum()) / len(ln)
            j += even * float(ln @ ln - mean * mean * len(ln))
            gd = 2.0 * even * d * (1.0 - mean / np.where(ln > 0, ln, np.inf))[:, None]
            g[:-1] -= gd
            g[1:] += gd
        if not np.isfinite(j):
            return 1e300, np.zeros_like(z)
        if state['scale'] is None:
            # Dimensionless objective: the tolerances then mean the same for every scenario.
            state['scale'] = max(abs(j), 1e-12)
        return j / state['scale'], g[1:-1].reshape(-1) / state['scale']

    def run(fun, z0: NDArray, maxiter: int) -> tuple[NDArray, int, int]:
        res = minimize(fun, z0, jac=True, method='L-BFGS-B', bounds=bounds,
                       options={'maxiter': maxiter, 'ftol': tolerance, 'gtol': 1e-7,
                                'maxcor': 20})
        return res.x, int(res.nit), int(res.nfev)

    iterations = evaluations = rounds = 0
    # With a cut-off the near threats are those of the path where they were picked; a path
    # that has moved far since may have flown towards threats it does not see, so re-pick
    # and continue until it stays within a quarter of the cut-off of the last pick.
    skip = (constrained_only and limits.any_constraint
            and check_limits(x, limits, floor).feasible)
    for _ in range(0 if skip else MAX_PAIR_ROUNDS if cutoff is not None else 1):
        pick_pairs(x)
        state['scale'] = None
        z, nit, nfev = run(objective, x[1:-1].reshape(-1), max_iterations)
        iterations, evaluations, rounds = iterations + nit, evaluations + nfev, rounds + 1
        moved = full(z)
        shift = float(np.max(np.linalg.norm(moved - x, axis=1)))
        x = moved
        if cutoff is None or shift < 0.25 * cutoff:
            break
    if not skip and (not limits.any_constraint or check_limits(x, limits, floor).feasible):
        return OptimisationResult(x, iterations, evaluations, rounds)

    # Equal spacing first: the constraint gradients grow as 1 / segment length, and the
    # unconstrained optimum bunches vertices at its corners.
    if not skip:
        x = resample(x, n - 1)
    pick_pairs(x)
    state['even'] = EVEN_SPACING_WEIGHT * spring_unit
    aim = limits.tightened(ANGLE_MARGIN_DEG, RADIUS_MARGIN)
    term = LimitTerm(aim, n)
    lam = np.zeros(term.rows)
    mu = PENALTY_START
    prev_violation, prev_f = np.inf, np.inf

    def lagrangian(z: NDArray) -> tuple[float, NDArray]:
        f, g = objective(z)
        if f >= 1e300:
            return f, g
        val, grad_c = term.penalty(full(z), lam, mu)
        return f + val, g + grad_c[1:-1].reshape(-1)

    best = (objective(x[1:-1].reshape(-1))[0], x) if skip else None
    for _ in range(MAX_OUTER):
        z, nit, nfev = run(lagrangian, x[1:-1].reshape(-1), constrained_iterations)
        iterations, evaluations, rounds = iterations + nit, evaluations + nfev, rounds + 1
        x = full(z)
        c = term.values(x)
        violation = float(np.max(-c, initial=0.0))
        lam = np.maximum(0.0, lam - mu * c)
        f = objective(z)[0]
        feasible = check_limits(x, limits, floor).feasible
        if feasible and (best is None or f < best[0]):
            best = (f, x)
        if feasible and abs(prev_f - f) <= OUTER_TOLERANCE * max(abs(f), 1.0):
            break
        if violation > 0.25 * prev_violation:
            mu *= PENALTY_GROWTH
        prev_violation, prev_f = violation, f
    if best is not None:
        return OptimisationResult(best[1], iterations, evaluations, rounds, True)
    # Stalled short of feasibility: the caller repairs (methods.repair) or reports.
    return OptimisationResult(x, iterations, evaluations, rounds, True)
