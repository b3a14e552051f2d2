"""The whole method: partition, search, smoothing, optional direct optimisation, cost.

Three methods:

* ``paper``: the paper as written: length-weighted Dijkstra from the node nearest the start
  to the node nearest the goal, mass-spring smoothing at a fixed k, angle check.
* ``improved``: the paper's Cases 1-3 together: Dijkstra on each edge's J (Case 2) for every
  pair of the K nearest entry and exit nodes (Case 1), the pair of least final J kept, then
  k swept over 500..3000 step 100 for least J among angle-feasible paths (Case 3).
* ``best``: one J-weighted Dijkstra with the start and goal joined to K candidates each,
  smoothing, then L-BFGS-B on J itself within the box and the angle limits, started from both
  the smoothed and the raw Dijkstra path; the lower J wins.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from threadpoolctl import threadpool_limits

from threat_planner.core.cost import Cost, path_cost
from threat_planner.errors import InputError, PlanningError
from threat_planner.core.optimisation import minimise_cost
from threat_planner.core.partition import build_network, Network
from threat_planner.core.search import (alternative_routes, dijkstra_pairs, edge_threat_costs,
                                        EdgeCosts, nearest_nodes, segment_costs)
from threat_planner.core.smoothing import AngleCheck, check_angles, resample, smooth
from threat_planner.core.threats import as_point, Box, ThreatField

METHODS = ('paper', 'improved', 'best')
#: Case 3's k sweep, from the paper: 500 <= k <= 3000 in steps of 100.
K_SWEEP = tuple(range(500, 3001, 100))
#: Segments and stopping tolerance of the coarse screening minimisation ('best').
COARSE_SEGMENTS = 8
COARSE_TOLERANCE = 1e-4
#: Largest (segment, threat) pairs per optimiser evaluation counted in full.
OPTIMISER_DENSE_PAIRS = 20_000
#: Optimiser cut-off beyond that, in typical threat spacings.
OPTIMISER_CUTOFF_SPACINGS = 3.0
#: Screened basins refined, best first, until one meets the angle limits ('best').
FEASIBILITY_TRIES = 3


@dataclass(frozen=True)
class PlannerConfig:
    """Planner settings; every field has a sensible default.

    Attributes:
        w: Threat weight in J = w J_R + (1-w) J_L, 0 < w < 1.
        method: 'paper', 'improved' or 'best'.
        k: Spring coefficient of the smoothing chain.
        auto_k: Sweep k over K_SWEEP for least J (Case 3); 'improved' always does.
        damping: Damping coefficient b between neighbouring masses (eq. 9-10).
        mass: Mass M of each chain point (eq. 14).
        q: Repulsion constant Q (eq. 13).
        n_points: Number of chain segments n (the chain has n+1 points).
        max_pitch_deg: Pitch limit [deg].
        max_turn_deg: Turn (steering) limit between consecutive segments [deg].
        entry_candidates: K nearest nodes tried as entry and as exit (Case 1).
        routes: Distinct network routes screened by 'best' (plus the straight line).
        box_divisions: Intervals per box edge of the auxiliary surface lattice.
        optimise: Run the direct J minimisation ('best' only).
        confine_to_box: Keep the optimised path inside the flight box; False lets the
            direct minimisation leave it (the reference yardstick's setting).
        max_smoothing_steps: Step limit of the chain integration.
    """

    w: float = 0.5
    method: str = 'best'
    k: float = 1000.0
    auto_k: bool = False
    damping: float = 20.0
    mass: float = 1.0
    q: float = 500.0
    n_points: int = 40
    max_pitch_deg: float = 45.0
    max_turn_deg: float = 60.0
    entry_candidates: int = 3
    routes: int = 6
    box_divisions: int = 2
    optimise: bool = True
    confine_to_box: bool = True
    max_smoothing_steps: int = 4000

    def validated(self) -> 'PlannerConfig':
        """Return self after checking every field's range.

        Raises:
            InputError: naming the field and its bad value.
        """
        checks = [
            ('w', 0.0 < self.w < 1.0, 'must satisfy 0 < w < 1'),
            ('method', self.method in METHODS, f'must be one of {", ".join(METHODS)}'),
            ('k', np.isfinite(self.k) and self.k > 0, 'must be > 0'),
            ('damping', np.isfinite(self.damping) and self.damping >= 0, 'must be >= 0'),
            ('mass', np.isfinite(self.mass) and self.mass > 0, 'must be > 0'),
            ('q', np.isfinite(self.q) and self.q >= 0, 'must be >= 0'),
            ('n_points', 2 <= self.n_points <= 10_000, 'must be in 2..10000'),
            ('max_pitch_deg', 0 < self.max_pitch_deg <= 90, 'must be in (0, 90]'),
            ('max_turn_deg', 0 < self.max_turn_deg <= 180, 'must be in (0, 180]'),
            ('entry_candidates', 1 <= self.entry_candidates <= 64, 'must be in 1..64'),
            ('routes', 1 <= self.routes <= 32, 'must be in 1..32'),
            ('box_divisions', 1 <= self.box_divisions <= 16, 'must be in 1..16'),
            ('max_smoothing_steps', self.max_smoothing_steps >= 0, 'must be >= 0'),
        ]
        for name, ok, why in checks:
            if not ok:
                raise InputError(f'{name}: {why}, got {getattr(self, name)!r}')
        return self


@dataclass
class PlanResult:
    """Everything a plan produced.

    Attributes:
        method: Method used.
        w: Threat weight used.
        network: The incentre network.
        entry: Entry node id (0-based).
        exit: Exit node id (0-based).
        node_sequence: Dijkstra node ids from entry to exit.
        initial_path: Start, the Dijkstra nodes, goal, (m, 3) [m].
        smoothed_path: Rest state of the mass-spring chain, (n+1, 3) [m]; None when
            'best' went straight to the direct minimisation.
        path: Final path, (n+1, 3) [m].
        initial_cost: Cost of initial_path.
        smoothed_cost: Cost of smoothed_path, or None.
        cost: Cost of the final path.
        k: Spring coefficient of the smoothing that produced the final path.
        angles: Angle check of the final path.
        smoothing_steps: Integration steps of the chosen smoothing.
        smoothing_converged: Whether that integration met its stopping rule.
        candidates: Final J for each (entry, exit) pair tried (Case 1), or empty.
        k_sweep: Final J (inf if infeasible) for each k tried (Case 3), or empty.
        seed: Which start the final path grew from ('route i' or 'straight line').
        edge_cutoff: Cut-off radius of the edge costs [m], None if exact.
        timings_ms: Wall time per stage [ms].
    """

    method: str
    w: float
    network: Network
    entry: int
    exit: int
    node_sequence: list[int]
    initial_path: NDArray
    smoothed_path: NDArray | None
    path: NDArray
    initial_cost: Cost
    smoothed_cost: Cost | None
    cost: Cost
    k: float
    angles: AngleCheck
    smoothing_steps: int
    smoothing_converged: bool
    candidates: dict[tuple[int, int], float] = field(default_factory=dict)
    k_sweep: dict[float, float] = field(default_factory=dict)
    seed: str = 'route 0'
    edge_cutoff: float | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)

    @property
    def feasible(self) -> bool:
        """Final path meets both angle limits."""
        return self.angles.feasible

    def summary(self) -> dict:
        """JSON-ready summary in the command line's ``--json`` layout."""
        return {
            'method': self.method,
            'w': self.w,
            'initial_path': self.initial_path.tolist(),
            'path': self.path.tolist(),
            'cost': {'initial': self.initial_cost.as_dict(),
                     'smoothed': None if self.smoothed_cost is None
                     else self.smoothed_cost.as_dict(),
                     'final': self.cost.as_dict()},
            'network': {'nodes': self.network.n_nodes, 'edges': self.network.n_edges},
            'entry': self.entry,
            'exit': self.exit,
            'node_sequence': self.node_sequence,
            # 'best' minimises J directly: no spring, no k (null rather than NaN in JSON).
            'k': self.k if np.isfinite(self.k) else None,
            'seed': self.seed,
            'feasible': self.feasible,
            'angles': {'max_pitch_deg': self.angles.max_pitch_deg,
                       'max_turn_deg': self.angles.max_turn_deg,
                       'pitch_ok': self.angles.pitch_ok, 'turn_ok': self.angles.turn_ok},
            'smoothing': {'steps': self.smoothing_steps,
                          'converged': self.smoothing_converged},
            'edge_cutoff_m': self.edge_cutoff,
            'timings_ms': self.timings_ms,
        }


class _Clock:
    """Accumulates wall time per named stage."""

    def __init__(self) -> None:
        self.ms: dict[str, float] = {}
        self._t0 = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.ms[stage] = self.ms.get(stage, 0.0) + 1e3 * (now - self._t0)
        self._t0 = now


@dataclass
class _Candidate:
    """One path under consideration, from its network route to its final form."""

    seq: list[int]
    initial: NDArray
    smoothed: NDArray | None
    smoothed_cost: Cost | None
    final: NDArray
    k: float
    steps: int
    converged: bool
    cost: Cost
    angles: AngleCheck
    seed: str = 'route 0'


def check_endpoints(start: ArrayLike, goal: ArrayLike, box: Box,
                    threats: ThreatField) -> tuple[NDArray, NDArray]:
    """Validate start and goal: finite, inside the box, not on a threat.

    Raises:
        InputError: naming the point and the problem.
    """
    out = []
    for name, value in (('start', start), ('goal', goal)):
        p = as_point(name, value)
        if not box.contains(p):
            raise InputError(f'{name}: {p.tolist()} is outside bounds '
                             f'{box.lo.tolist()}..{box.hi.tolist()}')
        if len(threats):
            d, i = threats.tree.query(p)
            if d <= 1e-9 * max(box.diagonal, 1.0):
                raise InputError(f'{name}: {p.tolist()} is on threat {int(i)}')
        out.append(p)
    return out[0], out[1]


def plan(threats: ThreatField, start: ArrayLike, goal: ArrayLike, box: Box,
         config: PlannerConfig = PlannerConfig(),
         progress: Callable[[int, int], None] | None = None) -> PlanResult:
    """Plan a path from start to goal through the threat field.

    Args:
        threats: Known radars.
        start: Start point S (3,) [m], inside the box.
        goal: Goal point T (3,) [m], inside the box.
        box: Flight box.
        config: Planner settings.
        progress: Optional callback (done, total) for long sweeps.

    Returns:
        The PlanResult.

    Raises:
        InputError: for a bad configuration, start or goal.
        PlanningError: if no path exists on the network.
    """
    config.validated()
    s, t = check_endpoints(start, goal, box, threats)
    # The optimisers make thousands of tiny BLAS calls; a threaded BLAS spends longer waking
    # its threads than computing, and far longer when the cores are busy (measured: 4x).
    with threadpool_limits(1, user_api='blas'):
        return _plan(threats, s, t, box, config, progress)


def _plan(threats: ThreatField, s: NDArray, t: NDArray, box: Box, config: PlannerConfig,
          progress: Callable[[int, int], None] | None) -> PlanResult:
    clock = _Clock()
    network = build_network(threats.positions, box, config.box_divisions)
    clock.lap('partition_ms')
    w = config.w
    lengths = network.edge_lengths
    edge_j: EdgeCosts | None = None
    if config.method != 'paper':
        edge_j = edge_threat_costs(network, threats, threats.typical_spacing(box),
                                   volume=float(np.prod(box.hi - box.lo)))
    clock.lap('edge_costs_ms')

    def smooth_seq(seq: list[int], k: float) -> _Candidate:
        initial = np.vstack([s, network.nodes[seq], t])
        # Network nodes may sit in the box's margin; the chain starts inside the box.
        chain = box.clip(resample(initial, config.n_points))
        r = smooth(chain, threats.positions, threats.intensities, k, config.damping,
                   config.mass, config.q, max_steps=config.max_smoothing_steps,
                   bounds=(box.lo, box.hi))
        pts = r.points
        c = path_cost(pts, threats.positions, threats.intensities, w)
        if not np.isfinite(c.J):
            # The chain came to rest on a threat (pinned there by a wall): the resampled
            # route itself is the better answer.
            pts = chain
            c = path_cost(pts, threats.positions, threats.intensities, w)
        return _Candidate(seq, initial, pts, c, pts, k, r.steps, r.converged, c,
                          check_angles(pts, config.max_pitch_deg, config.max_turn_deg))

    candidates: dict[tuple[int, int], float] = {}
    k_sweep: dict[float, float] = {}
    if config.method == 'paper':
        entry = int(nearest_nodes(network, s, 1)[0])
        exit_ = int(nearest_nodes(network, t, 1)[0])
        seq = dijkstra_pairs(network, lengths, np.array([entry]), np.array([exit_]))
        clock.lap('search_ms')
        best = smooth_seq(seq[(entry, exit_)][0], config.k)
        clock.lap('smoothing_ms')
    else:
        entries = nearest_nodes(network, s, config.entry_candidates)
        exits = nearest_nodes(network, t, config.entry_candidates)
        weights = edge_j.weights(lengths, w)
        if config.method == 'improved':
            routes = dijkstra_pairs(network, weights, entries, exits)
            clock.lap('search_ms')
            best = None
            for n_done, (pair, (seq, _)) in enumerate(routes.items(), 1):
                cand = smooth_seq(seq, config.k)
                candidates[pair] = cand.cost.J
                if best is None or cand.cost.J < best.cost.J:
                    best = cand
                if progress:
                    progress(n_done, len(routes) + len(K_SWEEP))
            clock.lap('smoothing_ms')
        else:
            legs_s, _ = segment_costs(np.repeat(s[None], len(entries), 0),
                                      network.nodes[entries], threats, edge_j.radius)
            legs_t, _ = segment_costs(network.nodes[exits], np.repeat(t[None], len(exits), 0),
                                      threats, edge_j.radius)
            len_s = np.linalg.norm(network.nodes[entries] - s, axis=1)
            len_t = np.linalg.norm(network.nodes[exits] - t, axis=1)
            routes = alternative_routes(network, weights, edge_j.combine(legs_s, len_s, w),
                                        entries, edge_j.combine(legs_t, len_t, w), exits,
                                        config.routes)
            clock.lap('search_ms')
            if not config.optimise:
                best = smooth_seq(routes[0], config.k)
                clock.lap('smoothing_ms')

    if config.method == 'improved' or (config.auto_k and config.method != 'best'):
        feasible_best = best if best.angles.feasible else None
        for n_done, k in enumerate(K_SWEEP, 1):
            cand = smooth_seq(best.seq, float(k))
            k_sweep[float(k)] = cand.cost.J if cand.angles.feasible else float('inf')
            if cand.angles.feasible and (feasible_best is None
                                         or cand.cost.J < feasible_best.cost.J):
                feasible_best = cand
            if progress:
                progress(len(candidates) + n_done, len(candidates) + len(K_SWEEP))
        best = feasible_best or best
        clock.lap('k_sweep_ms')

    if config.method == 'best' and config.optimise:
        best = _optimise_routes(routes, network, s, t, threats, box, config, clock)

    if not np.isfinite(best.cost.J):
        raise PlanningError(
            f'cost: no path with a finite J was found (J = {best.cost.J}); the intensities '
            f'(largest {float(threats.intensities.max(initial=0.0)):.3g}) overflow double '
            'precision or a threat blocks the way')
    timings = dict(clock.ms)
    timings['total_ms'] = float(sum(clock.ms.values()))
    seq = best.seq
    return PlanResult(
        method=config.method, w=w, network=network, entry=seq[0] if seq else -1,
        exit=seq[-1] if seq else -1, node_sequence=list(seq), initial_path=best.initial,
        smoothed_path=best.smoothed, path=best.final,
        initial_cost=path_cost(best.initial, threats.positions, threats.intensities, w),
        smoothed_cost=best.smoothed_cost, cost=best.cost, k=best.k, angles=best.angles,
        smoothing_steps=best.steps, smoothing_converged=best.converged,
        candidates=candidates, k_sweep=k_sweep, seed=best.seed,
        edge_cutoff=None if edge_j is None else edge_j.radius, timings_ms=timings)


def _optimiser_cutoff(segments: int, threats: ThreatField, spacing: float) -> float | None:
    """Cut-off radius for a minimisation over ``segments`` segments, None to count all.

    Every threat is counted while that costs at most OPTIMISER_DENSE_PAIRS pairs per
    evaluation. Beyond, far threats are dropped: a much wider radius than the edge costs'
    because the optimiser follows the gradient, which a cut-off distorts, into places the
    Dijkstra route never went.
    """
    if segments * len(threats) <= OPTIMISER_DENSE_PAIRS:
        return None
    return OPTIMISER_CUTOFF_SPACINGS * spacing


def _optimise_routes(routes: list[list[int]], network: Network, s: NDArray, t: NDArray,
                     threats: ThreatField, box: Box, config: PlannerConfig,
                     clock: _Clock) -> _Candidate:
    """Screen every route and the straight line coarsely, then refine the lowest-J one.

    Each route lies in its own basin of J (it passes the threats on its own sides); a cheap
    coarse minimisation of each tells the basins apart before the fine one runs once.
    """
    w = config.w
    bounds = box if config.confine_to_box else None
    spacing = threats.typical_spacing(box)
    f_pos, f_int = threats.positions, threats.intensities
    # The straight line is the other natural start, and wins when length dominates.
    seeds = [(f'route {i}', seq) for i, seq in enumerate(routes)] + [('straight line', [])]
    screened = []
    for name, seq in seeds:
        initial = np.vstack([s, network.nodes[seq], t]) if seq else np.vstack([s, t])
        coarse = minimise_cost(resample(initial, COARSE_SEGMENTS), threats, w, bounds,
                               90.0, 180.0, cutoff=_optimiser_cutoff(COARSE_SEGMENTS, threats,
                                                                     spacing),
                               tolerance=COARSE_TOLERANCE).points
        screened.append((path_cost(coarse, f_pos, f_int, w).J, name, seq, coarse))
    screened.sort(key=lambda item: item[0])
    clock.lap('screening_ms')
    best: _Candidate | None = None
    # Refine the best basin; if the angle limits cannot be met there, the next basins get
    # a chance (a feasible path beats any infeasible one, then lower J wins).
    for _, name, seq, coarse in screened[:FEASIBILITY_TRIES]:
        opt = minimise_cost(resample(coarse, config.n_points), threats, w, bounds,
                            config.max_pitch_deg, config.max_turn_deg,
                            cutoff=_optimiser_cutoff(config.n_points, threats, spacing))
        seq = seq or routes[0]   # the line won: report the best route as the initial path
        cand = _Candidate(seq, np.vstack([s, network.nodes[seq], t]), None, None, opt.points,
                          float('nan'), 0, True, path_cost(opt.points, f_pos, f_int, w),
                          check_angles(opt.points, config.max_pitch_deg,
                                       config.max_turn_deg), seed=name)
        if best is None or ((cand.angles.feasible, -cand.cost.J)
                            > (best.angles.feasible, -best.cost.J)):
            best = cand
        if best.angles.feasible:
            break
    clock.lap('optimisation_ms')
    return best
