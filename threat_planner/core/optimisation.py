"""Direct minimisation of J (beyond the paper): L-BFGS-B on the closed-form cost.

The smoothed chain balances springs against repulsion, which is not the same as least J.
Here the interior vertices move to minimise J itself with its exact gradient
(``cost.cost_and_gradient``), inside the flight box (bounds), and where the unconstrained
minimum breaks the pitch or turn limit, SLSQP takes over with the limits as smooth
inequality constraints. A faint spring term keeps vertices evenly spread, because J alone
does not care where along the path they sit and bunched vertices make turn angles
meaningless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from threat_planner.core.cost import cost_and_gradient
from threat_planner.core.smoothing import check_angles
from threat_planner.core.threats import Box, ThreatField

#: Weight of the even-spacing term relative to the length cost.
SPACING_WEIGHT = 1e-3
#: Most pair re-picks of a cut-off minimisation.
MAX_PAIR_ROUNDS = 6
#: Safety margin kept inside the angle limits while optimising [deg].
ANGLE_MARGIN_DEG = 0.25


@dataclass(frozen=True)
class OptimisationResult:
    """Outcome of the direct J minimisation.

    Attributes:
        points: Optimised path, (n+1, 3) [m].
        iterations: L-BFGS-B iterations over all penalty rounds.
        evaluations: Cost-and-gradient evaluations.
        rounds: Stages run: 1 (L-BFGS-B only), 2 or 3 (then SLSQP runs for the angle limits).
    """

    points: NDArray
    iterations: int
    evaluations: int
    rounds: int


def angle_constraints(points: NDArray, max_pitch_deg: float, max_turn_deg: float
                      ) -> tuple[NDArray, NDArray]:
    """Angle limits as smooth inequalities g >= 0 over the interior vertices, with Jacobian.

    Pitch of segment d: sin^2(limit) |d|^2 - d_z^2 >= 0. Turn between segments d, e:
    d.e - cos(limit) |d| |e| >= 0. Both avoid the kinks of |.| and acos.

    Args:
        points: Path, (n+1, 3) [m].
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn limit [deg].

    Returns:
        ``(g (2n-1,), jacobian (2n-1, 3(n-1)))`` with respect to the interior vertices.
    """
    d = np.diff(points, axis=0)
    n = len(d)
    l2 = np.einsum('ik,ik->i', d, d)
    ln = np.sqrt(l2)
    sp2 = np.sin(np.radians(max_pitch_deg)) ** 2
    c = np.cos(np.radians(max_turn_deg))
    g = np.concatenate([sp2 * l2 - d[:, 2] ** 2,
                        np.einsum('ik,ik->i', d[:-1], d[1:]) - c * ln[:-1] * ln[1:]])
    safe = np.where(ln > 0, ln, 1.0)
    jd = np.zeros((2 * n - 1, n, 3))
    i = np.arange(n)
    jd[i, i] = 2.0 * sp2 * d
    jd[i, i, 2] -= 2.0 * d[:, 2]
    k = np.arange(n - 1)
    jd[n + k, k] = d[1:] - c * (ln[1:] / safe[:-1])[:, None] * d[:-1]
    jd[n + k, k + 1] = d[:-1] - c * (ln[:-1] / safe[1:])[:, None] * d[1:]
    # d_j = x_{j+1} - x_j, so vertex j gets -dg/dd_j + dg/dd_{j-1}.
    jx = np.zeros((2 * n - 1, n + 1, 3))
    jx[:, :-1] -= jd
    jx[:, 1:] += jd
    return g, jx[:, 1:-1].reshape(2 * n - 1, -1)


def minimise_cost(points: NDArray, threats: ThreatField, w: float, box: Box | None,
                  max_pitch_deg: float, max_turn_deg: float, cutoff: float | None = None,
                  max_iterations: int = 1000, tolerance: float = 1e-6,
                  constrained_iterations: int = 100) -> OptimisationResult:
    """Minimise J over the interior vertices within the box and the angle limits.

    L-BFGS-B first minimises J within the box alone, which is fast; if the result breaks an
    angle limit, SLSQP continues from it with the limits as constraints (see
    angle_constraints), which restores feasibility within a few iterations and then lowers
    J while keeping it.

    Args:
        points: Starting path, (n+1, 3) [m]; the ends stay fixed.
        threats: The threat field.
        w: Threat weight, 0 < w < 1.
        box: Flight box (bounds for every vertex), or None for no bounds.
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn limit [deg].
        cutoff: If set, count only threats within this distance of each segment [m]; the
            pairs are re-picked whenever the path has moved a quarter of it.
        max_iterations: L-BFGS-B iteration limit.
        tolerance: Stop when an iteration lowers J by less than this fraction; 1e-6 put J
            within 0.05% of the yardstick on the bundled scenarios at a tenth of the
            iterations full convergence takes.
        constrained_iterations: SLSQP iteration limit.

    Returns:
        The OptimisationResult.
    """
    x = np.array(points, float)
    n = len(x)
    if n < 3:
        return OptimisationResult(x, 0, 0, 0)
    j_l0 = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum()) or 1.0
    spring = SPACING_WEIGHT * (1.0 - w) * (n - 1) / j_l0
    bounds = (None if box is None else
              [(lo, hi) for _ in range(n - 2) for lo, hi in zip(box.lo, box.hi)])
    ends = (x[0].copy(), x[-1].copy())
    state = {'pairs': None, 'scale': None}

    def pick_pairs(p: NDArray) -> None:
        if cutoff is not None:
            seg, thr, _ = threats.near_pairs(p[:-1], p[1:], cutoff)
            state['pairs'] = (seg, thr)

    def objective(z: NDArray) -> tuple[float, NDArray]:
        p = np.vstack([ends[0], z.reshape(-1, 3), ends[1]])
        j, g = cost_and_gradient(p, threats.positions, threats.intensities, w,
                                 state['pairs'])
        d = np.diff(p, axis=0)
        j += spring * float(np.sum(d * d))
        g[:-1] -= 2.0 * spring * d
        g[1:] += 2.0 * spring * d
        if not np.isfinite(j):
            return 1e300, np.zeros_like(z)
        if state['scale'] is None:
            # Dimensionless objective: the optimisers' tolerances then mean the same
            # for every scenario.
            state['scale'] = max(abs(j), 1e-12)
        return j / state['scale'], g[1:-1].reshape(-1) / state['scale']

    iterations = evaluations = 0
    # With a cut-off the near threats are those of the path where they were picked; a path
    # that has moved far since may have flown towards threats it does not see, so re-pick
    # and continue until it stays within a quarter of the cut-off of the last pick.
    for _ in range(MAX_PAIR_ROUNDS if cutoff is not None else 1):
        pick_pairs(x)
        state['scale'] = None
        res = minimize(objective, x[1:-1].reshape(-1), jac=True, method='L-BFGS-B',
                       bounds=bounds, options={'maxiter': max_iterations, 'ftol': tolerance,
                                               'gtol': 1e-7, 'maxcor': 20})
        iterations += int(res.nit)
        evaluations += int(res.nfev)
        moved = np.vstack([ends[0], res.x.reshape(-1, 3), ends[1]])
        shift = float(np.max(np.linalg.norm(moved - x, axis=1)))
        x = moved
        if cutoff is None or shift < 0.25 * cutoff:
            break
    stages = 1
    if not check_angles(x, max_pitch_deg, max_turn_deg).feasible:
        pick_pairs(x)
        pitch = max(max_pitch_deg - ANGLE_MARGIN_DEG, 0.0)
        turn = max(max_turn_deg - ANGLE_MARGIN_DEG, 0.0)

        def limits(z: NDArray) -> NDArray:
            return angle_constraints(np.vstack([ends[0], z.reshape(-1, 3), ends[1]]),
                                     pitch, turn)[0]

        def limits_jac(z: NDArray) -> NDArray:
            return angle_constraints(np.vstack([ends[0], z.reshape(-1, 3), ends[1]]),
                                     pitch, turn)[1]

        # SLSQP usually restores feasibility within its first iterations; when a hard start
        # needs longer, one restart from where it stopped (fresh Hessian) is cheap insurance.
        for _ in range(2):
            res = minimize(objective, x[1:-1].reshape(-1), jac=True, method='SLSQP',
                           bounds=bounds,
                           constraints=[{'type': 'ineq', 'fun': limits, 'jac': limits_jac}],
                           options={'maxiter': constrained_iterations, 'ftol': tolerance})
            iterations += int(res.nit)
            evaluations += int(res.nfev)
            stages += 1
            x = np.vstack([ends[0], res.x.reshape(-1, 3), ends[1]])
            if check_angles(x, max_pitch_deg, max_turn_deg).feasible:
                break
    return OptimisationResult(x, iterations, evaluations, stages)
