"""Direct minimisation of the detection objective inside the box and the flight limits.

The objective is w H + (1 - w) L / L_0 (:mod:`.hazard` gives H with its exact gradient on a
fixed quadrature layout), or, under a bound on P_detect, L / L_0 with H <= -ln(1 - P) as
one more constraint. The interior vertices move by scipy's L-BFGS-B inside the box (the
floor raised by the minimum altitude); the flight limits (the fillet rule of
:mod:`threat_planner.core.optimise.limits`, the same compiled constraint term as method
``best``) and the bound enter as a Powell-Hestenes-Rockafellar augmented Lagrangian whose
multipliers are updated between rounds, and the layout (and the seen pieces under terrain
masking) is made again at each round, so every round is a smooth problem.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from threat_planner.core.detection.hazard import layout, path_hazard
from threat_planner.core.detection.kernels import compiled_hazard
from threat_planner.core.detection.model import DetectionModel
from threat_planner.core.optimise.limit_kernels import LimitTerm
from threat_planner.core.optimise.limits import FlightLimits, meets_limits
from threat_planner.core.optimise.optimisation import aim, PENALTY_GROWTH, PENALTY_START

__all__ = ['DetectionProblem', 'Outcome', 'minimise_detection', 'refine_slsqp']

#: Weight of the even-spacing term (variance of the segment lengths over the mean's square):
#: the objective does not care where along the path its vertices sit, and bunched ones
#: turn on tiny circles.
EVEN_WEIGHT = 1e-3
#: Most augmented-Lagrangian rounds, and L-BFGS-B iterations per round.
MAX_ROUNDS = 8
MAX_ITER = 300
#: L-BFGS-B's relative stopping tolerance on the objective (which is ~1).
LBFGS_FTOL = 1e-10
#: Stop once a feasible round changed the objective by less than this (relative).
ROUND_TOLERANCE = 1e-5
#: SLSQP: most iterations a run, its tolerance, most runs (each on a layout made from the
#: last one's end), and the move below which a run ends them [fraction of L_0].
SLSQP_ITER = 200
SLSQP_FTOL = 1e-10
SLSQP_LAYOUTS = 3
SLSQP_SETTLED = 1e-3
#: A bound on H is aimed this far inside (relative), so the exact check passes.
BOUND_MARGIN = 1e-6


@dataclass(frozen=True)
class DetectionProblem:
    """What the detection objective of one plan depends on.

    Attributes
    ----------
    positions, intensities : ndarray
        Threats (N, 3) [m] and F (N,).
    model : DetectionModel
        The radar model.
    w : float
        Weight of H (the length's is 1 - w); ignored under a bound.
    l0 : float
        Straight-line distance start-goal [m].
    lo, hi : ndarray
        The box the interior vertices keep to (3,) [m], the floor raised by the altitude.
    limits : FlightLimits
        The flight limits.
    floor_z : float
        The box floor [m] (the altitude limit's reference).
    pieces_of : callable, optional
        points -> the seen (segment, threat, f0, f1) pieces under terrain masking.
    h_max : float, optional
        Largest H allowed (a bound on P_detect); None: no bound.

    """

    positions: NDArray
    intensities: NDArray
    model: DetectionModel
    w: float
    l0: float
    lo: NDArray
    hi: NDArray
    limits: FlightLimits
    floor_z: float
    pieces_of: Callable[[NDArray], tuple] | None = None
    h_max: float | None = None

    def hazard(self, points: NDArray) -> float:
        """Exact H of a path."""
        pieces = None if self.pieces_of is None else self.pieces_of(points)
        return path_hazard(points, self.positions, self.intensities, self.model,
                           pieces).hazard

    def objective(self, points: NDArray, h: float | None = None) -> float:
        """Exact objective: w H + (1 - w) L / L_0, or L / L_0 under a bound."""
        length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
        if self.h_max is not None:
            return length / self.l0
        h = self.hazard(points) if h is None else h
        return self.w * h + (1.0 - self.w) * length / self.l0

    def feasible(self, points: NDArray, h: float | None = None) -> bool:
        """Within the box, the flight limits and the bound (exact checks)."""
        inside = bool(np.all(points[1:-1] >= self.lo - 1e-9)
                      and np.all(points[1:-1] <= self.hi + 1e-9))
        if not (inside and meets_limits(points, self.limits, self.floor_z)):
            return False
        if self.h_max is None:
            return True
        return (self.hazard(points) if h is None else h) <= self.h_max


@dataclass(frozen=True)
class Outcome:
    """A minimisation's end: the path, its exact H and objective, and feasibility."""

    points: NDArray
    hazard: float
    objective: float
    feasible: bool
    rounds: int
    evaluations: int


def _length_terms(points: NDArray, l0: float, even: float) -> tuple[float, float, NDArray]:
    """(L / L_0, even-spacing term, gradient of both) of a polyline."""
    d = np.diff(points, axis=0)
    seg = np.linalg.norm(d, axis=1)
    unit = d / np.where(seg > 0, seg, 1.0)[:, None]
    n = len(seg)
    mean = seg.sum() / n
    spread = float(np.sum((seg - mean) ** 2)) / max(mean * mean, 1e-300) / n
    # d spread / d seg_k = 2 (seg_k - mean) / (n mean^2) - 2 spread / (n mean)
    dseg = 1.0 / l0 + even * (2.0 * (seg - mean) / (n * mean * mean) - 2.0 * spread / (n * mean))
    grad = np.zeros_like(points)
    grad[:-1] -= dseg[:, None] * unit
    grad[1:] += dseg[:, None] * unit
    return float(seg.sum()) / l0, even * spread, grad


def minimise_detection(x0: NDArray, prob: DetectionProblem, rounds: int = MAX_ROUNDS,
                       max_iter: int = MAX_ITER, penalty: float = PENALTY_START
                       ) -> Outcome:
    """Minimise the detection objective from path x0 (its ends fixed) under the limits.

    Returns the best feasible iterate of the rounds (least objective) or, where none was
    feasible, the last one.
    """
    inner = len(x0) - 2
    x = np.clip(np.asarray(x0, float).copy(), np.vstack([x0[0], *[prob.lo] * inner, x0[-1]]),
                np.vstack([x0[0], *[prob.hi] * inner, x0[-1]]))
    n1 = len(x)
    term = LimitTerm(aim(prob.limits), n1) if prob.limits.any_constraint else None
    lam = np.zeros(term.rows) if term is not None else np.zeros(0)
    lam_h, mu = 0.0, float(penalty)
    bounded = prob.h_max is not None
    w_h = 0.0 if bounded else prob.w
    w_l = 1.0 if bounded else 1.0 - prob.w
    target = prob.h_max * (1.0 - BOUND_MARGIN) if bounded else None
    bounds = [(lo, hi) for _ in range(n1 - 2) for lo, hi in zip(prob.lo, prob.hi)]
    best: tuple | None = None
    last_value, last_violation, evaluations = np.inf, np.inf, 0
    for r in range(rounds):
        pieces = None if prob.pieces_of is None else prob.pieces_of(x)
        lay = layout(x, prob.positions, prob.intensities, prob.model, pieces)

        def fun(z: NDArray) -> tuple[float, NDArray]:
            nonlocal evaluations
            evaluations += 1
            p = x.copy()
            p[1:-1] = z.reshape(-1, 3)
            per, gh = compiled_hazard(p, prob.positions, prob.intensities, prob.model, lay)
            h = float(per.sum())
            lf, spread, gl = _length_terms(p, prob.l0, EVEN_WEIGHT)
            value = w_h * h + w_l * lf + spread
            grad = w_h * gh + w_l * gl
            if bounded:
                # The length term's gradient carries 1 / L_0 already; the spread's too.
                g = (target - h) / target
                s = max(0.0, lam_h - mu * g)
                value += (s * s - lam_h * lam_h) / (2.0 * mu)
                grad = grad + (s / target) * gh
            if term is not None:
                pen, pg = term.penalty(p, lam, mu)
                value += pen
                grad = grad + pg
            return value, grad[1:-1].reshape(-1)

        res = minimize(fun, x[1:-1].reshape(-1), jac=True, method='L-BFGS-B', bounds=bounds,
                       options={'maxiter': max_iter, 'ftol': LBFGS_FTOL, 'gtol': 1e-9})
        x = x.copy()
        x[1:-1] = res.x.reshape(-1, 3)
        violation = 0.0
        if term is not None:
            c = term.values(x)
            violation = float(np.max(-c, initial=0.0))
            lam = np.maximum(0.0, lam - mu * c)
        h = prob.hazard(x)
        if bounded:
            g = (target - h) / target
            violation = max(violation, -g)
            lam_h = max(0.0, lam_h - mu * g)
        value = prob.objective(x, h)
        feasible = prob.feasible(x, h)
        if feasible and (best is None or value < best[2]):
            best = (x.copy(), h, value)
        if feasible and abs(last_value - value) <= ROUND_TOLERANCE * max(abs(value), 1e-12):
            break
        if violation > 0.25 * last_violation:
            mu *= PENALTY_GROWTH
        last_value, last_violation = value, violation
    if best is not None:
        return Outcome(best[0], best[1], best[2], True, r + 1, evaluations)
    h = prob.hazard(x)
    return Outcome(x, h, prob.objective(x, h), False, r + 1, evaluations)


def refine_slsqp(x0: NDArray, prob: DetectionProblem, max_iter: int = SLSQP_ITER,
                 layouts: int = SLSQP_LAYOUTS) -> Outcome:
    """Minimise the detection objective from x0 by SLSQP, limits and bound as constraints.

    The limits are :func:`~threat_planner.core.optimise.limits.constraint_values` of the
    aimed limits with their exact Jacobian (compiled, :class:`LimitTerm`); the layout is
    made again from each run's end, up to `layouts` runs, while the run moved the path.
    """
    x = np.asarray(x0, float).copy()
    n1 = len(x)
    term = LimitTerm(aim(prob.limits), n1)
    bounded = prob.h_max is not None
    w_h = 0.0 if bounded else prob.w
    w_l = 1.0 if bounded else 1.0 - prob.w
    target = prob.h_max * (1.0 - BOUND_MARGIN) if bounded else None
    bounds = [(lo, hi) for _ in range(n1 - 2) for lo, hi in zip(prob.lo, prob.hi)]
    evaluations, runs = 0, 0
    best: tuple | None = None

    def full(z: NDArray) -> NDArray:
        p = x.copy()
        p[1:-1] = z.reshape(-1, 3)
        return p

    for runs in range(1, layouts + 1):
        pieces = None if prob.pieces_of is None else prob.pieces_of(x)
        lay = layout(x, prob.positions, prob.intensities, prob.model, pieces)
        cache: dict = {}

        def hazard(z: NDArray) -> tuple[float, NDArray]:
            key = z.tobytes()
            if key not in cache:
                nonlocal evaluations
                evaluations += 1
                per, gh = compiled_hazard(full(z), prob.positions, prob.intensities,
                                          prob.model, lay)
                cache.clear()
                cache[key] = (float(per.sum()), gh[1:-1].reshape(-1))
            return cache[key]

        def fun(z: NDArray) -> tuple[float, NDArray]:
            p = full(z)
            lf, spread, gl = _length_terms(p, prob.l0, EVEN_WEIGHT)
            value, grad = w_l * lf + spread, w_l * gl[1:-1].reshape(-1)
            if w_h:
                h, gh = hazard(z)
                value, grad = value + w_h * h, grad + w_h * gh
            return value, grad

        limit_cache: dict = {}

        def limit_rows(z: NDArray) -> tuple[NDArray, NDArray]:
            # SLSQP asks for the values and the Jacobian at each point: one pass for both.
            key = z.tobytes()
            if key not in limit_cache:
                g, jac = term.values_jacobian(full(z))
                limit_cache.clear()
                limit_cache[key] = (g, jac[:, 1:-1, :].reshape(-1, 3 * (n1 - 2)))
            return limit_cache[key]

        constraints = []
        if prob.limits.any_constraint:
            constraints.append({'type': 'ineq', 'fun': lambda z: limit_rows(z)[0],
                                'jac': lambda z: limit_rows(z)[1]})
        if bounded:
            constraints.append({'type': 'ineq',
                                'fun': lambda z: np.array([(target - hazard(z)[0]) / target]),
                                'jac': lambda z: (-hazard(z)[1] / target)[None, :]})
        res = minimize(fun, x[1:-1].reshape(-1), jac=True, method='SLSQP', bounds=bounds,
                       constraints=constraints,
                       options={'maxiter': max_iter, 'ftol': SLSQP_FTOL})
        moved = float(np.max(np.abs(res.x - x[1:-1].reshape(-1)), initial=0.0))
        x = full(res.x)
        h = prob.hazard(x)
        value = prob.objective(x, h)
        feasible = prob.feasible(x, h)
        if feasible and (best is None or value < best[2]):
            best = (x.copy(), h, value)
        if moved < SLSQP_SETTLED * prob.l0:
            break
    if best is not None:
        return Outcome(best[0], best[1], best[2], True, runs, evaluations)
    h = prob.hazard(x)
    return Outcome(x, h, prob.objective(x, h), False, runs, evaluations)
