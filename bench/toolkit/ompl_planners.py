"""OMPL on the planner's own J, and the fast closed-form J of one segment it needs.

* :class:`SegmentCost` is J of one straight segment against every threat, written for the
  many one-segment calls OMPL makes (numpy over the N threats); it agrees with the
  library's ``path_cost`` to rounding, so every method is judged by the same evaluator.
* :func:`run_ompl` runs an OMPL planner (RRT*, BIT*, ...) in a ``RealVectorStateSpace(3)``
  over the flight box, optimising that very J through a Python ``OptimizationObjective``
  whose ``motionCost`` is the segment's closed-form J and whose ``stateCost`` is zero.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.cost.closed_form import pair_integrals, path_cost
from threat_planner.core.world.threats import Box, ThreatField

try:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou
except ImportError:  # pragma: no cover - exercised only without OMPL
    ob = og = ou = None

# Below this ratio h / |t| the fast segment formula would lose digits to cancellation
# (relative error ~ eps * (|t| / h)^2); such pairs go to the library's series instead.
_CANCEL_RATIO = 1e-3


class SegmentCost:
    """Closed-form J of one straight segment, fast for one segment and N threats.

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Threat positions [m].
    intensities : array_like, shape (N,)
        Threat intensities F.
    w : float
        Threat weight of J = w J_R + (1 - w) J_L.

    Notes
    -----
    With u the unit direction, t1 < t2 the segment's ends measured from the threat's foot
    point and h the threat's distance from the line, the integral of 1/(t^2 + h^2)^2 is
    ``(dtheta + h (t2/(t2^2+h^2) - t1/(t1^2+h^2))) / (2 h^3)`` with
    ``dtheta = atan2(h L, h^2 + t1 t2)``. Pairs where that loses digits (the threat almost
    on the segment's line beyond an end, or almost touching it) are handed to the library's
    :func:`threat_planner.core.cost.closed_form.pair_integrals`, so the result matches
    ``path_cost``.
    """

    def __init__(self, positions: ArrayLike, intensities: ArrayLike, w: float) -> None:
        self.positions = np.ascontiguousarray(np.asarray(positions, float).reshape(-1, 3))
        self.intensities = np.ascontiguousarray(np.asarray(intensities, float).reshape(-1))
        self.w = float(w)
        self.calls = 0

    def threat(self, a: NDArray, b: NDArray) -> float:
        """Return J_R of the segment a -> b [m]: sum_i F_i int ds / |x(s) - p_i|^4.

        ``inf`` through a threat.
        """
        p = self.positions
        if len(p) == 0:
            return 0.0
        d = b - a
        length = math.sqrt(float(d @ d))
        if length == 0.0:
            return 0.0
        u = d / length
        e = a - p
        t1 = e @ u
        perp = e - t1[:, None] * u
        h2 = np.einsum('ij,ij->i', perp, perp)
        h = np.sqrt(h2)
        t2 = t1 + length
        with np.errstate(divide='ignore', invalid='ignore'):
            dtheta = np.arctan2(h * length, h2 + t1 * t2)
            val = (dtheta + h * (t2 / (t2 * t2 + h2) - t1 / (t1 * t1 + h2))) / (2.0 * h2 * h)
        bad = (h < _CANCEL_RATIO * np.minimum(np.abs(t1), np.abs(t2))) | (h < 1e-6 * length)
        if bad.any():
            k = int(bad.sum())
            val[bad] = pair_integrals(np.broadcast_to(a, (k, 3)), np.broadcast_to(b, (k, 3)),
                                      p[bad])
        return float(val @ self.intensities)

    def __call__(self, a: NDArray, b: NDArray) -> float:
        """Return J = w J_R + (1 - w) L of the segment a -> b and count the call."""
        self.calls += 1
        d = b - a
        return self.w * self.threat(a, b) + (1.0 - self.w) * math.sqrt(float(d @ d))


def ompl_available() -> bool:
    """Return whether the OMPL Python bindings imported."""
    return ob is not None


if ob is not None:
    class ThreatObjective(ob.OptimizationObjective):
        """OMPL objective optimising the planner's own J along straight motions.

        ``motionCost`` is the closed-form J of the straight motion (via
        :class:`SegmentCost`), ``stateCost`` is the identity (zero) cost, and
        ``motionCostHeuristic`` is the admissible (1 - w) * distance, used by BIT* as its
        cost-to-come and cost-to-go heuristic. Costs combine by addition (the default), so
        OMPL's cost of a path is exactly J of that polyline.

        Parameters
        ----------
        si : ompl.base.SpaceInformation
            Space information of a 3-D ``RealVectorStateSpace``.
        seg : SegmentCost
            The segment cost to optimise.

        Notes
        -----
        In the ompl 2.0 Python bindings a Python override of
        ``StateCostIntegralObjective.stateCost`` is silently ignored (that route optimises
        length only), while overrides of ``OptimizationObjective.motionCost`` and
        ``motionCostHeuristic`` are called: ``motion_calls`` and ``heuristic_calls``
        count them so the benchmark can check.
        """

        def __init__(self, si: 'ob.SpaceInformation', seg: SegmentCost) -> None:
            super().__init__(si)
            self.seg = seg
            self.one_minus_w = 1.0 - seg.w
            self.motion_calls = 0
            self.heuristic_calls = 0
            self.state_calls = 0

        def stateCost(self, s: 'ob.State') -> 'ob.Cost':  # noqa: N802 (OMPL's name)
            """Return the identity (zero) cost: all of J sits in the motions."""
            self.state_calls += 1
            return self.identityCost()

        def motionCost(self, s1: 'ob.State', s2: 'ob.State') -> 'ob.Cost':  # noqa: N802
            """Return J of the straight motion s1 -> s2."""
            self.motion_calls += 1
            return ob.Cost(self.seg(np.array((s1[0], s1[1], s1[2])),
                                    np.array((s2[0], s2[1], s2[2]))))

        def motionCostHeuristic(self, s1: 'ob.State',  # noqa: N802 (OMPL's name)
                                s2: 'ob.State') -> 'ob.Cost':
            """Return the admissible lower bound (1 - w) * |s2 - s1| of the motion's J."""
            self.heuristic_calls += 1
            dx, dy, dz = s1[0] - s2[0], s1[1] - s2[1], s1[2] - s2[2]
            return ob.Cost(self.one_minus_w * math.sqrt(dx * dx + dy * dy + dz * dz))


def set_ompl_quiet(seed: int | None = None) -> None:
    """Silence OMPL's informational logging and optionally fix its random seed.

    Parameters
    ----------
    seed : int, optional
        Seed for OMPL's global random generator (effective only before its first use).
    """
    if ou is None:
        return
    ou.setLogLevel(ou.LOG_ERROR)
    if seed is not None:
        ou.RNG.setSeed(int(seed))


def _ompl_space(box: Box, valid: Callable | None = None, resolution: float | None = None
                ) -> tuple['ob.RealVectorStateSpace', 'ob.SpaceInformation']:
    """Return the box as a state space; every state valid unless `valid` says otherwise."""
    space = ob.RealVectorStateSpace(3)
    bounds = ob.RealVectorBounds(3)
    for i in range(3):
        bounds.setLow(i, float(box.lo[i]))
        bounds.setHigh(i, float(box.hi[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(ob.AllValidStateValidityChecker(si) if valid is None
                               else valid)
    if resolution is not None:
        si.setStateValidityCheckingResolution(resolution)
    si.setup()
    return space, si


def _state(space: 'ob.RealVectorStateSpace', xyz: NDArray) -> 'ob.State':
    s = space.allocState()
    for i in range(3):
        s[i] = float(xyz[i])
    return s


@dataclass
class OmplProblem:
    """An OMPL problem set up to optimise J, ready to solve.

    Attributes
    ----------
    space, si, pdef : OMPL objects
        State space, space information and problem definition.
    objective : ThreatObjective
        The J objective.
    seg : SegmentCost
        The segment cost behind it.
    """

    space: object
    si: object
    pdef: object
    objective: object
    seg: SegmentCost


def ompl_problem(threats: ThreatField, start: NDArray, goal: NDArray, box: Box, w: float,
                 seg: SegmentCost | None = None, valid: Callable | None = None,
                 resolution: float | None = None) -> OmplProblem:
    """Build the OMPL problem of going from start to goal in the box at least J.

    Parameters
    ----------
    threats, start, goal, box, w
        The problem: threats, end points [m], flight box (the state space's bounds) and
        threat weight.
    seg : SegmentCost, optional
        The motions' cost (default: the closed-form J of these threats at w).
    valid : callable, optional
        State validity checker (default: every state in the box is valid).
    resolution : float, optional
        Motion checking resolution, a fraction of the space's extent (OMPL's default).

    Returns
    -------
    OmplProblem
        The problem, objective installed.
    """
    if ob is None:
        raise RuntimeError('OMPL Python bindings are not installed')
    space, si = _ompl_space(box, valid, resolution)
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(_state(space, start), _state(space, goal))
    if seg is None:
        seg = SegmentCost(threats.positions, threats.intensities, w)
    objective = ThreatObjective(si, seg)
    pdef.setOptimizationObjective(objective)
    return OmplProblem(space, si, pdef, objective, seg)


def path_points(path: object) -> NDArray:
    """Return an OMPL geometric path's states as an (n, 3) array."""
    return np.array([[s[0], s[1], s[2]] for s in path.getStates()], dtype=float)


def run_ompl(planner: str, threats: ThreatField, start: NDArray, goal: NDArray, box: Box,
             w: float, budgets_s: Sequence[float]) -> list[dict]:
    """Run one OMPL planner on J and record its best path at each time budget.

    The planner is solved once up to the smallest budget, then resumed (RRT* and BIT*
    keep their tree between ``solve`` calls) up to each larger one, so the result at a
    budget is what a run with that budget alone would return.

    Parameters
    ----------
    planner : str
        Name of a planner class in ``ompl.geometric`` (``'RRTstar'``, ``'BITstar'``,
        ``'InformedRRTstar'``, ...).
    threats, start, goal, box, w
        The problem, as :func:`ompl_problem` takes it.
    budgets_s : sequence of float
        Cumulative time budgets [s].

    Returns
    -------
    list of dict
        Per budget (ascending): ``budget_s``, ``elapsed_s``, ``status``, ``exact``,
        ``J`` (our ``path_cost`` of the path, inf if none), ``J_ompl`` (OMPL's own cost of
        it), ``rel_diff`` (their relative difference), ``n_states``, ``motion_calls``,
        ``heuristic_calls``, ``state_calls`` and ``path``.
    """
    prob = ompl_problem(threats, start, goal, box, w)
    pl = getattr(og, planner)(prob.si)
    pl.setProblemDefinition(prob.pdef)
    pl.setup()
    out = []
    elapsed = 0.0
    for budget in sorted(budgets_s):
        t0 = time.perf_counter()
        status = pl.solve(max(float(budget) - elapsed, 1e-3))
        elapsed += time.perf_counter() - t0
        obj = prob.objective
        rec = {'budget_s': float(budget), 'elapsed_s': elapsed, 'status': status.asString(),
               'exact': bool(prob.pdef.hasExactSolution()), 'motion_calls': obj.motion_calls,
               'heuristic_calls': obj.heuristic_calls, 'state_calls': obj.state_calls,
               'J': math.inf, 'J_ompl': math.inf, 'rel_diff': math.nan, 'n_states': 0,
               'path': []}
        if rec['exact']:
            path = prob.pdef.getSolutionPath()
            pts = path_points(path)
            j_ompl = float(path.cost(obj).value())
            j = path_cost(pts, threats.positions, threats.intensities, w).J
            rec.update(J=j, J_ompl=j_ompl, rel_diff=abs(j_ompl - j) / max(abs(j), 1e-300),
                       n_states=len(pts), path=pts.tolist())
        out.append(rec)
    pl.clear()  # free the tree: the bindings keep these objects alive
    return out
