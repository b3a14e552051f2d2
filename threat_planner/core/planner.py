"""Plan a path: partition, edge costs, then the chosen method, and the exact cost of it.

The methods themselves are in :mod:`threat_planner.core.methods.registry`; settings in
:mod:`threat_planner.core.inputs.config`; the result in :mod:`threat_planner.core.result`.
"""

from __future__ import annotations

from contextlib import contextmanager, nullcontext
import dataclasses
from functools import lru_cache
import threading
from typing import Callable, ContextManager, Iterator, TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.cost.closed_form import Cost
from threat_planner.core.detection.model import DetectionModel
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.settings import METHODS
from threat_planner.core.methods.problem import Candidate, Clock, Problem
from threat_planner.core.methods.refining import converge, refine
from threat_planner.core.methods.registry import K_SWEEP, METHOD_FUNCTIONS
from threat_planner.core.methods.warm import warm_path
from threat_planner.core.network.partition import build_network, paper_network
from threat_planner.core.network.search import edge_threat_costs
from threat_planner.core.optimise.smoothing import check_angles
from threat_planner.core.result import PlanResult
from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.threats import Box, check_endpoints, ThreatField
from threat_planner.errors import InputError, PlanningError

if TYPE_CHECKING:
    from threadpoolctl import ThreadpoolController

__all__ = ['K_SWEEP', 'METHODS', 'PlanResult', 'PlannerConfig', 'check_endpoints', 'plan']


def plan(threats: ThreatField, start: ArrayLike, goal: ArrayLike, box: Box,
         config: PlannerConfig = PlannerConfig(),
         progress: Callable[[int, int], None] | None = None,
         warm_start: PlanResult | None = None,
         airspace: Airspace | None = None,
         on_initial: Callable[[NDArray, Cost], None] | None = None) -> PlanResult:
    """Plan a path from start to goal through the threat field.

    Args:
        threats: Known radars.
        start: Start point S (3,) [m], inside the box.
        goal: Goal point T (3,) [m], inside the box.
        box: Flight box.
        config: Planner settings.
        progress: Optional callback (done, total) for long sweeps.
        warm_start: The previous plan; after a small change (core/methods/warm.py states the
            rule) its path is refined instead of planning from scratch.
        airspace: No-fly zones and terrain to respect (method 'best' only), or None.
        on_initial: Optional callback (points (M, 3) [m], exact Cost) with the network
            route as soon as the search has found it, before smoothing and optimisation
            (a cold plan without airspace; a caller that may stop the plan keeps it).

    Returns:
        The PlanResult.

    Raises:
        InputError: for a bad configuration, start or goal.
        PlanningError: if no path exists on the network.
    """
    config.validated()
    height = float(box.hi[2] - box.lo[2])
    if config.min_altitude_m >= height and config.min_altitude_m > 0:
        raise InputError(f'min_altitude_m: must be below the box height {height:g}, '
                         f'got {float(config.min_altitude_m):g}')
    s, t = check_endpoints(start, goal, box, threats)
    if len(threats) >= LOADER_THREATS:
        _load_kernels()
    if airspace:   # airspace hook (issue 12)
        if config.method != 'best':
            raise InputError(f'method: no-fly zones and terrain need method best, '
                             f'got {config.method}')
        airspace.check_point('start', s)
        airspace.check_point('goal', t)
    else:
        airspace = None
    with _one_blas_thread(len(threats), airspace is not None
                          or config.cost_model == 'detection'), _joining_kernels():
        note = ''
        if warm_start is not None and airspace is None:
            warm = _plan_warm(warm_start, threats, s, t, box, config)
            if isinstance(warm, PlanResult):
                return warm
            note = warm
        result = _plan(threats, s, t, box, config, progress, airspace, on_initial)
        result.warm_note = note
        return result


#: Threats from which plan() holds BLAS to one thread. A threaded BLAS on a busy machine
#: slowed big fields (beside two busy loops, big300_0 + 1,000 + 5,000 threats 1.29x slower
#: without the limit); below, no plan was faster with it, quiet or busy (21 bundled cases
#: 0.94x / 0.97x, 60 and 120 threats 1.00x), and finding the BLAS libraries to limit
#: (realpath of ~100 loaded libraries) cost 6-9 ms of a process's first plan
#: (bench/results/blas_threads.md).
BLAS_LIMIT_THREATS = 250


def _one_blas_thread(n_threats: int, airspace: bool) -> ContextManager:
    """Return a context holding BLAS to one thread for a big field or an airspace.

    Plans with zones or terrain depend on the BLAS thread count (the six airspace
    scenarios at w 0.5, one thread against two: J apart by up to 2.3e-5 relative), and
    from there by whole basins (a live airspace recording replayed 0.17 % apart): they are
    planned on one thread, as their replays are. The other plans were the same bit for bit
    on one and two threads (test_planner). A detection plan spends its time in SLSQP's
    small dense QPs, where a second BLAS thread only spins (uniform20_0, ellipsoid RCS:
    3.5 s either way, 7.1 s of CPU against 3.9 s): one thread.
    """
    if n_threats < BLAS_LIMIT_THREATS and not airspace:
        return nullcontext()
    return _blas().limit(limits=1, user_api='blas')


@lru_cache(maxsize=1)
def _blas() -> ThreadpoolController:
    """Return the loaded BLAS libraries, found once."""
    from threadpoolctl import ThreadpoolController
    return ThreadpoolController()


#: Threats from which a process's first plan loads the kernels while it tetrahedralises
#: (below, the Delaunay is too short to hide the loading: first plans with the loading
#: thread, 20 threats 0.42 -> 0.58-0.64 s, 1,000 threats 0.62-0.65 -> 0.66 s; 10,000
#: threats 1.69-1.73 -> 1.37-1.46 s).
LOADER_THREATS = 2_000
_LOADER: dict = {'thread': None, 'lock': threading.Lock()}


def _load_kernels() -> None:
    """Start loading the compiled kernels in a thread, once a process.

    numba's first call in a process sets up its compiler and each kernel's first call
    loads it from the cache: 0.2-0.25 s before a fresh process's first plan could start
    (10,000 threats: the partition took 573-593 ms in a fresh process against 230-290
    in-process). Qhull releases the GIL, so a thread that plans a tiny field meanwhile
    overlaps it with the Delaunay (348-366 ms); the plan joins it before it returns.
    """
    with _LOADER['lock']:
        if _LOADER['thread'] is not None:
            return
        _LOADER['thread'] = threading.Thread(target=_tiny_plan, daemon=True,
                                             name='threat_planner kernels')
    _LOADER['thread'].start()


@contextmanager
def _joining_kernels() -> Iterator[None]:
    """Join the loading thread on the way out of a plan (not from the thread itself)."""
    try:
        yield
    finally:
        thread = _LOADER['thread']
        if thread is not None and thread is not threading.current_thread():
            thread.join()


def _tiny_plan() -> None:
    """Plan a 16-threat field with the default settings; cost edges under a cut-off.

    16 threats: enough for the surface lattice's costs to run in parallel, as in a big plan.
    """
    from threat_planner.core.cost.near_kernels import near_segment_costs
    rng = np.random.default_rng(0)
    threats = ThreatField.from_arrays(rng.uniform(20.0, 80.0, (16, 3)), np.full(16, 1e4))
    box = Box.from_corners([0.0, 0.0, 0.0], [100.0, 100.0, 100.0])
    try:
        near_segment_costs(np.zeros((2, 3)), np.ones((2, 3)), threats.positions,
                           threats.intensities, 5.0)
        _plan(threats, np.array([0.0, 0.0, 50.0]), np.array([100.0, 100.0, 50.0]), box,
              PlannerConfig(), None)
    except Exception:  # noqa: BLE001 - a kernel it failed to load, the plan loads itself
        pass


def _plan_warm(previous: PlanResult, threats: ThreatField, s: NDArray, t: NDArray, box: Box,
               config: PlannerConfig) -> PlanResult | str:
    """Replan warm from the previous plan, or return the reason to plan cold."""
    clock = Clock()
    path, note = warm_path(previous, threats, s, t, box, config)
    if path is None:
        return note
    problem = Problem(threats=threats, s=s, t=t, box=box, config=config,
                      network=previous.network, edge_j=None, clock=clock)
    if config.cost_model == 'detection':   # issue 43: the previous basin, refined again
        from threat_planner.core.detection.plan import replan_detection
        cand = replan_detection(problem, path, previous)
        clock.lap('warm_ms')
        if cand is None:
            return 'cold: the warm detection replan broke a limit or its bound'
        return _result(problem, cand, note)
    cand = refine(problem, path, previous.node_sequence, previous.seed, tolerance=1e-8,
                  warm=True)
    if cand.limits_bound:
        # Ended as a cold plan ends (refining.converge): from a start that broke a limit,
        # the rounds at FINAL_EVEN alone ended 6e-5 above the cold plan (test_plan_limits).
        cand = converge(problem, cand)
    cand = _no_higher_than_its_start(problem, cand, path)
    cand.basin_margin = previous.basin_margin
    clock.lap('warm_ms')
    if previous.feasible and not cand.limit_check.feasible:
        return 'cold: the warm result broke a limit the previous plan met'
    return _result(problem, cand, note)


def _no_higher_than_its_start(p: Problem, cand: Candidate, start: NDArray) -> Candidate:
    """Return a warm replan's candidate, or its start where that meets the limits lower.

    Under the optimiser's cut-off the rounds lower a J without the far threats, and a
    replan could end above the path it started from (bench perturbation's moves of n120
    seed 0 w 0.8 with the limits off: up to +0.1 % over the previous plan).
    """
    if len(start) != len(cand.final):
        return cand
    cost, check = p.cost(start), p.check(start)
    if not (check.feasible and cost.J < cand.cost.J):
        return cand
    cfg = p.config
    return dataclasses.replace(cand, final=start, cost=cost, limit_check=check,
                               angles=check_angles(start, cfg.max_pitch_deg,
                                                   cfg.max_turn_deg))


def _plan(threats: ThreatField, s: NDArray, t: NDArray, box: Box, config: PlannerConfig,
          progress: Callable[[int, int], None] | None,
          airspace: Airspace | None = None,
          on_initial: Callable[[NDArray, Cost], None] | None = None) -> PlanResult:
    clock = Clock()
    if config.network == 'threats':
        network = paper_network(threats.positions, box)
    else:
        network = build_network(threats.positions, box, config.box_divisions)
    clock.lap('partition_ms')
    edge_j = None
    if config.method != 'paper' and airspace is None:
        edge_j = edge_threat_costs(network, threats, threats.typical_spacing(box),
                                   volume=float(np.prod(box.hi - box.lo)))
    clock.lap('edge_costs_ms')
    problem = Problem(threats=threats, s=s, t=t, box=box, config=config, network=network,
                      edge_j=edge_j, clock=clock, progress=progress, airspace=airspace,
                      on_initial=on_initial)
    if config.cost_model == 'detection':   # issue 43: from method best's plan
        from threat_planner.core.detection.plan import plan_detection
        best = plan_detection(problem)
        if airspace is not None:
            network, edge_j = problem.network, None
    elif airspace is not None:   # airspace hook (issue 12)
        from threat_planner.core.methods.in_airspace import plan_in_airspace
        best = plan_in_airspace(problem)
        network = problem.network
        edge_j = None
    else:
        best = METHOD_FUNCTIONS[config.method](problem)
    if not np.isfinite(best.cost.J):
        raise PlanningError(
            f'cost: no path with a finite J was found (J = {best.cost.J}); the intensities '
            f'(largest {float(threats.intensities.max(initial=0.0)):.3g}) overflow double '
            'precision or a threat blocks the way')
    return _result(problem, best)


def _result(problem: Problem, best: Candidate, warm_note: str = '') -> PlanResult:
    """Build the PlanResult of a problem's chosen candidate."""
    config, network, edge_j = problem.config, problem.network, problem.edge_j
    timings = dict(problem.clock.ms)
    timings['total_ms'] = float(sum(problem.clock.ms.values()))
    seq = best.seq
    initial = best.initial
    return PlanResult(
        method=config.method, w=config.w, network=network, entry=seq[0] if seq else -1,
        exit=seq[-1] if seq else -1, node_sequence=list(seq), initial_path=initial,
        smoothed_path=best.smoothed, path=best.final, initial_cost=problem.cost(initial),
        smoothed_cost=best.smoothed_cost, cost=best.cost, k=best.k, angles=best.angles,
        smoothing_steps=best.steps, smoothing_converged=best.converged,
        candidates=problem.candidates, k_sweep=problem.k_sweep, seed=best.seed,
        edge_cutoff=None if edge_j is None else edge_j.radius, timings_ms=timings,
        limits=problem.limits, limit_check=best.limit_check or problem.check(best.final),
        warm=bool(warm_note), warm_note=warm_note, basin_margin=best.basin_margin,
        problem=(problem.threats, problem.s, problem.t, problem.box, config),
        clearance=None if problem.airspace is None
        else problem.airspace.clearance(best.final), speed_mps=config.speed_mps,
        cost_model=config.cost_model, detection_model=DetectionModel.of(config),
        masking=problem.airspace.terrain if problem.airspace is not None
        and problem.airspace.masking else None,
        objective=getattr(best, 'objective', None),
        detection_status=getattr(best, 'detection_status', ''))
