"""Pieces of the benchmark: reference loader, fast segment cost, OMPL runner, floors.

Everything here scores paths with the library's closed-form cost
(:func:`threat_planner.core.cost.closed_form.path_cost`), so every method in the
benchmark is judged by the same evaluator:

* :func:`load_reference` reads ``reference.json`` (``"scenario@w" -> {"J", "seconds"}``).
* :class:`SegmentCost` is J of one straight segment against every threat, written for the
  many one-segment calls OMPL makes (numpy over the N threats, arrays precomputed); it
  agrees with ``path_cost`` to rounding.
* :func:`run_ompl` runs an OMPL planner (RRT*, BIT*, ...) in a ``RealVectorStateSpace(3)``
  over the flight box, optimising that very J through a Python ``OptimizationObjective``
  whose ``motionCost`` is the segment's closed-form J and whose ``stateCost`` is zero.
* :func:`build_grid` and :func:`grid_floor` are the plain grid floor: a 26-connected grid
  over the box, exact J of every edge, Dijkstra.
* :func:`scale_problem` makes the scaling sweep's problems at the 20-threat density.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path
import time
from typing import Sequence

import _repo  # noqa: F401  (puts the repository root on sys.path)
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from threat_planner.core.cost.closed_form import pair_integrals, path_cost, segment_threat_costs
from threat_planner.core.world.threats import Box, ThreatField

try:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou
except ImportError:  # pragma: no cover - exercised only without OMPL
    ob = og = ou = None

ROOT = _repo.ROOT
#: PlannerConfig fields that switch the UAV angle limits off (pitch <= 90, turn <= 180
#: always hold): the rules OMPL, the grid floor and the reference play by.
NO_ANGLE_LIMITS = {'max_pitch_deg': 90.0, 'max_turn_deg': 180.0}
#: Where the shared scenarios and reference.json live.
SHARED_SCENARIOS = Path('/work/shared/scenarios')
#: The bundled copies of the small scenarios (no scale*.yaml).
LOCAL_SCENARIOS = ROOT / 'test' / 'data'

# Below this ratio h / |t| the fast segment formula would lose digits to cancellation
# (relative error ~ eps * (|t| / h)^2); such pairs go to the library's series instead.
_CANCEL_RATIO = 1e-3


def default_scenario_dir() -> Path:
    """Return the shared scenario directory if present, else the bundled copies.

    Returns
    -------
    Path
        A directory holding ``*.yaml`` scenarios and ``reference.json``.
    """
    return SHARED_SCENARIOS if (SHARED_SCENARIOS / 'reference.json').exists() \
        else LOCAL_SCENARIOS


def load_reference(path: str | Path) -> dict[tuple[str, float], dict[str, float]]:
    """Read the yardstick's ``reference.json``.

    Parameters
    ----------
    path : str or Path
        The JSON file, keyed ``"scenario@w"`` with values ``{"J": ..., "seconds": ...}``.

    Returns
    -------
    dict
        ``(scenario, w) -> {"J": float, "seconds": float}``, w rounded to 6 decimals.
    """
    data = json.loads(Path(path).read_text())
    out: dict[tuple[str, float], dict[str, float]] = {}
    for key, value in data.items():
        name, _, w = key.rpartition('@')
        if not name:
            raise ValueError(f'{path}: key {key!r} is not "scenario@w"')
        out[(name, round(float(w), 6))] = {'J': float(value['J']),
                                           'seconds': float(value.get('seconds', math.nan))}
    return out


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
        """Return J_R of the segment a -> b.

        Parameters
        ----------
        a, b : ndarray, shape (3,)
            Segment ends [m].

        Returns
        -------
        float
            sum_i F_i * integral ds / |x(s) - p_i|^4 (``inf`` through a threat).
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


def _ompl_space(box: Box) -> tuple['ob.RealVectorStateSpace', 'ob.SpaceInformation']:
    space = ob.RealVectorStateSpace(3)
    bounds = ob.RealVectorBounds(3)
    for i in range(3):
        bounds.setLow(i, float(box.lo[i]))
        bounds.setHigh(i, float(box.hi[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(ob.AllValidStateValidityChecker(si))
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


def ompl_problem(threats: ThreatField, start: NDArray, goal: NDArray, box: Box,
                 w: float) -> OmplProblem:
    """Build the OMPL problem of going from start to goal in the box at least J.

    Parameters
    ----------
    threats : ThreatField
        The threats.
    start, goal : ndarray, shape (3,)
        End points [m].
    box : Box
        Flight box: the state space's bounds.
    w : float
        Threat weight.

    Returns
    -------
    OmplProblem
        The problem, objective installed.
    """
    if ob is None:
        raise RuntimeError('OMPL Python bindings are not installed')
    space, si = _ompl_space(box)
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(_state(space, start), _state(space, goal))
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
    threats : ThreatField
        The threats.
    start, goal : ndarray, shape (3,)
        End points [m].
    box : Box
        Flight box.
    w : float
        Threat weight.
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


@dataclass
class GridGraph:
    """A 26-connected grid over the box with the start and goal joined in.

    Attributes
    ----------
    nodes : ndarray, shape (M, 3)
        Grid nodes, then the start (index M-2) and the goal (index M-1) [m].
    edge_a, edge_b : ndarray, shape (E,)
        Edge end indices.
    length : ndarray, shape (E,)
        Edge lengths [m].
    threat : ndarray, shape (E,)
        Edge threat costs J_R (exact, closed form).
    build_s : float
        Seconds spent building the graph and its edge costs.
    """

    nodes: NDArray
    edge_a: NDArray
    edge_b: NDArray
    length: NDArray
    threat: NDArray
    build_s: float

    @property
    def start(self) -> int:
        """Index of the start node."""
        return len(self.nodes) - 2

    @property
    def goal(self) -> int:
        """Index of the goal node."""
        return len(self.nodes) - 1


def _grid_edges(n: int) -> tuple[NDArray, NDArray]:
    """Both end indices of every 26-neighbour edge of an n x n x n grid (each once)."""
    idx = np.arange(n ** 3).reshape(n, n, n)
    src, dst = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if (dx, dy, dz) <= (0, 0, 0):
                    continue
                sl_a, sl_b = [], []
                for dd in (dx, dy, dz):
                    sl_a.append(slice(max(0, -dd), n - max(0, dd)))
                    sl_b.append(slice(max(0, dd), n - max(0, -dd)))
                src.append(idx[tuple(sl_a)].ravel())
                dst.append(idx[tuple(sl_b)].ravel())
    return np.concatenate(src), np.concatenate(dst)


def _cell_neighbours(point: NDArray, lo: NDArray, step: NDArray, n: int) -> NDArray:
    """Grid node indices within one step (per axis) of the node nearest the point."""
    i0 = np.clip(np.rint((point - lo) / step).astype(int), 0, n - 1)
    rng = [np.arange(max(0, i - 1), min(n, i + 2)) for i in i0]
    ii, jj, kk = np.meshgrid(*rng, indexing='ij')
    return ((ii * n + jj) * n + kk).ravel()


def build_grid(threats: ThreatField, start: NDArray, goal: NDArray, box: Box,
               n: int = 21) -> GridGraph:
    """Build the grid floor's graph and every edge's exact J_R.

    Parameters
    ----------
    threats : ThreatField
        The threats.
    start, goal : ndarray, shape (3,)
        End points [m]; each is joined to the (up to 27) grid nodes around it.
    box : Box
        Flight box, gridded with n nodes per axis.
    n : int
        Nodes per axis.

    Returns
    -------
    GridGraph
        The graph; J_R of all edges comes from one vectorised
        :func:`threat_planner.core.cost.closed_form.segment_threat_costs` call.
    """
    t0 = time.perf_counter()
    axes = [np.linspace(box.lo[i], box.hi[i], n) for i in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing='ij')
    grid = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    step = (box.hi - box.lo) / (n - 1)
    a, b = _grid_edges(n)
    s_idx, g_idx = n ** 3, n ** 3 + 1
    near_s = _cell_neighbours(np.asarray(start, float), box.lo, step, n)
    near_g = _cell_neighbours(np.asarray(goal, float), box.lo, step, n)
    a = np.concatenate([a, np.full(len(near_s), s_idx), near_g])
    b = np.concatenate([b, near_s, np.full(len(near_g), g_idx)])
    nodes = np.vstack([grid, start, goal])
    length = np.linalg.norm(nodes[b] - nodes[a], axis=1)
    threat = segment_threat_costs(nodes[a], nodes[b], threats.positions, threats.intensities)
    return GridGraph(nodes, a, b, length, threat, time.perf_counter() - t0)


def grid_floor(graph: GridGraph, threats: ThreatField, w: float
               ) -> tuple[NDArray, float, float, float]:
    """Least-J path on the grid by Dijkstra.

    Parameters
    ----------
    graph : GridGraph
        From :func:`build_grid`.
    threats : ThreatField
        The same threats, to score the path.
    w : float
        Threat weight.

    Returns
    -------
    path : ndarray, shape (k, 3)
        Start, grid nodes, goal [m].
    J : float
        ``path_cost(path).J``.
    graph_J : float
        Dijkstra's distance (sum of edge J), equal to J up to rounding.
    seconds : float
        Search time (excluding the graph build).
    """
    t0 = time.perf_counter()
    weight = w * graph.threat + (1.0 - w) * graph.length
    ok = np.isfinite(weight)
    # csgraph drops explicit zeros; only a start or goal sitting on a node gives one.
    weight = np.where(weight > 0, weight, 1e-300)
    m = len(graph.nodes)
    mat = coo_matrix((weight[ok], (graph.edge_a[ok], graph.edge_b[ok])), shape=(m, m)).tocsr()
    dist, pred = dijkstra(mat, directed=False, indices=graph.start, return_predecessors=True)
    if not np.isfinite(dist[graph.goal]):
        raise RuntimeError('grid floor: goal unreachable')
    seq = [graph.goal]
    while seq[-1] != graph.start:
        seq.append(int(pred[seq[-1]]))
    pts = graph.nodes[seq[::-1]]
    keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])
    pts = pts[keep]
    seconds = time.perf_counter() - t0
    j = path_cost(pts, threats.positions, threats.intensities, w).J
    return pts, j, float(dist[graph.goal]), seconds


def scale_problem(n: int, seed: int = 0) -> tuple[ThreatField, NDArray, NDArray, Box]:
    """Make a random problem with n threats at the density of the 20-threat scenarios.

    Threats are uniform in a cube of side ``100 (n / 20)^(1/3)`` m (100 m for 20), with
    intensities uniform in [1e5, 4e5] like ``uniform20_*``; start and goal sit at opposite
    corners at mid height, like ``scale1000.yaml``.

    Parameters
    ----------
    n : int
        Number of threats.
    seed : int
        Random seed (the problem for a given (n, seed) is always the same).

    Returns
    -------
    threats, start, goal, box
        The problem.
    """
    side = 100.0 * (n / 20.0) ** (1.0 / 3.0)
    rng = np.random.default_rng([seed, n])
    positions = rng.uniform(0.0, side, size=(n, 3))
    intensities = rng.uniform(1e5, 4e5, size=n)
    box = Box.from_corners([0.0, 0.0, 0.0], [side, side, side])
    start = np.array([0.0, 0.0, side / 2])
    goal = np.array([side, side, side / 2])
    return ThreatField.from_arrays(positions, intensities), start, goal, box


def moved_threats(threats: ThreatField, diagonal: float, seed: int = 7,
                  fraction: float = 0.005) -> ThreatField:
    """Return the threats each moved by at most ``fraction`` of the box diagonal.

    The speed bench's small change for warm replans: every coordinate shifted uniformly by
    up to ``fraction * diagonal / sqrt(3)`` [m] (random ``seed``), intensities kept.
    """
    rng = np.random.default_rng(seed)
    shift = rng.uniform(-1, 1, threats.positions.shape) * fraction * diagonal / np.sqrt(3)
    return ThreatField.from_arrays(threats.positions + shift, threats.intensities)
