"""Direct minimisation of J (beyond the paper): L-BFGS-B on the closed-form cost.

The smoothed chain balances springs against repulsion, which is not the same as least J.
Here the interior vertices move to minimise J itself with its exact gradient
(``cost.cost_and_gradient``), inside the flight box (L-BFGS-B bounds), while the pitch and
turn limits enter as quadratic penalties that are raised until the limits hold. A faint
spring term keeps vertices evenly spread, because J alone does not care where along the
path they sit and bunched vertices make turn angles meaningless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from threat_planner.cost import cost_and_gradient
from threat_planner.smoothing import check_angles
from threat_planner.threats import Box, ThreatField

#: Weight of the even-spacing term relative to the length cost.
SPACING_WEIGHT = 1e-3
#: Safety margin kept inside the angle limits while optimising [deg].
ANGLE_MARGIN_DEG = 0.25


@dataclass(frozen=True)
class OptimisationResult:
    """Outcome of the direct J minimisation.

    Attributes:
        points: Optimised path, (n+1, 3) [m].
        iterations: L-BFGS-B iterations over all penalty rounds.
        evaluations: Cost-and-gradient evaluations.
        rounds: Penalty rounds run.
    """

    points: NDArray
    iterations: int
    evaluations: int
    rounds: int


def angle_penalty(points: NDArray, max_pitch_deg: float, max_turn_deg: float
                  ) -> tuple[float, NDArray]:
    """Quadratic penalty on pitch and turn limit excess, and its gradient.

    The turn term is sum max(0, cos(limit) - u_{j-1}.u_j)^2 and the pitch term
    sum max(0, |u_z| - sin(limit))^2, u being unit segment directions.

    Args:
        points: Path, (n+1, 3) [m].
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn limit [deg].

    Returns:
        ``(penalty, gradient (n+1, 3))``.
    """
    d = np.diff(points, axis=0)
    ln = np.linalg.norm(d, axis=1)
    ln = np.where(ln > 0, ln, 1e-12)
    u = d / ln[:, None]
    grad_d = np.zeros_like(d)
    pen = 0.0

    s_max = np.sin(np.radians(max_pitch_deg))
    excess = np.abs(u[:, 2]) - s_max
    on = excess > 0
    if np.any(on):
        pen += float(np.sum(excess[on] ** 2))
        sgn = np.sign(u[on, 2])
        # d u_z / d d = (e_z - u_z u) / |d|
        du = (np.array([0.0, 0.0, 1.0]) - u[on, 2:3] * u[on]) / ln[on, None]
        grad_d[on] += (2.0 * excess[on] * sgn)[:, None] * du

    c_min = np.cos(np.radians(max_turn_deg))
    cos_t = np.einsum('ik,ik->i', u[:-1], u[1:])
    short = c_min - cos_t
    on = short > 0
    if np.any(on):
        pen += float(np.sum(short[on] ** 2))
        idx = np.flatnonzero(on)
        ua, ub = u[idx], u[idx + 1]
        # d cos / d d_prev = (u_next - cos u_prev) / |d_prev|, and symmetrically.
        ga = (ub - cos_t[idx, None] * ua) / ln[idx, None]
        gb = (ua - cos_t[idx, None] * ub) / ln[idx + 1, None]
        coef = (-2.0 * short[idx])[:, None]
        np.add.at(grad_d, idx, coef * ga)
        np.add.at(grad_d, idx + 1, coef * gb)

    grad = np.zeros_like(points)
    grad[:-1] -= grad_d
    grad[1:] += grad_d
    return pen, grad


def minimise_cost(points: NDArray, threats: ThreatField, w: float, box: Box,
                  max_pitch_deg: float, max_turn_deg: float, cutoff: float | None = None,
                  max_iterations: int = 400, rounds: int = 4) -> OptimisationResult:
    """Minimise J over the interior vertices within the box and the angle limits.

    Args:
        points: Starting path, (n+1, 3) [m]; the ends stay fixed.
        threats: The threat field.
        w: Threat weight, 0 < w < 1.
        box: Flight box (bounds for every vertex).
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn limit [deg].
        cutoff: If set, count only threats within this distance of each segment (pairs
            refreshed every round) [m]; None counts all.
        max_iterations: L-BFGS-B iteration limit per round.
        rounds: Most penalty rounds; each multiplies the penalty weight by 10.

    Returns:
        The OptimisationResult.
    """
    x = np.array(points, float)
    n = len(x)
    if n < 3:
        return OptimisationResult(x, 0, 0, 0)
    pitch_lim = max(max_pitch_deg - ANGLE_MARGIN_DEG, 0.0)
    turn_lim = max(max_turn_deg - ANGLE_MARGIN_DEG, 0.0)
    j_l0 = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum()) or 1.0
    spring = SPACING_WEIGHT * (1.0 - w) * (n - 1) / j_l0
    bounds = [(lo, hi) for _ in range(n - 2) for lo, hi in zip(box.lo, box.hi)]
    ends = (x[0].copy(), x[-1].copy())
    iterations = evaluations = 0
    mu = 0.0
    done = 0
    for done in range(1, rounds + 1):
        pairs = None
        if cutoff is not None:
            seg, thr, _ = threats.near_pairs(x[:-1], x[1:], cutoff)
            pairs = (seg, thr)
        scale = None

        def objective(z: NDArray) -> tuple[float, NDArray]:
            nonlocal scale
            p = np.vstack([ends[0], z.reshape(-1, 3), ends[1]])
            j, g = cost_and_gradient(p, threats.positions, threats.intensities, w, pairs)
            d = np.diff(p, axis=0)
            j += spring * float(np.sum(d * d))
            g[:-1] -= 2.0 * spring * d
            g[1:] += 2.0 * spring * d
            if mu > 0:
                pen, gp = angle_penalty(p, pitch_lim, turn_lim)
                j += mu * pen
                g += mu * gp
            if not np.isfinite(j):
                return 1e300, np.zeros_like(z)
            if scale is None:
                scale = max(abs(j), 1e-12)
            return j / scale, g[1:-1].reshape(-1) / scale

        res = minimize(objective, x[1:-1].reshape(-1), jac=True, method='L-BFGS-B',
                       bounds=bounds, options={'maxiter': max_iterations, 'ftol': 1e-12,
                                               'gtol': 1e-9, 'maxcor': 20})
        iterations += int(res.nit)
        evaluations += int(res.nfev)
        x = np.vstack([ends[0], res.x.reshape(-1, 3), ends[1]])
        if check_angles(x, max_pitch_deg, max_turn_deg).feasible:
            # With a cut-off, one more round re-picks the near threats of the moved path.
            if cutoff is None or done >= 2:
                break
        else:
            # The penalty is dimensionless, J is not: weigh it against the path's own length.
            mu = j_l0 if mu == 0 else mu * 10.0
    return OptimisationResult(x, iterations, evaluations, done)
