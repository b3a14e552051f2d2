"""Refining one start on J within the box and the flight limits, and converging the end.

:func:`refine` runs :func:`.optimisation.minimise_cost` from a path of ``n_points``
segments (coarse to fine, or warm from a previous plan) and scores the result exactly;
:func:`converge` runs the last rounds again from a bound winner's own path until they stop
gaining. Method ``best`` (:mod:`.best`) refines its seeds and its winner with them; the
planner (:mod:`..planner`) its warm replans and :mod:`..robust` its pictures.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.methods.problem import Candidate, Problem
from threat_planner.core.optimise.optimisation import (EVEN_SPACING_WEIGHT, is_crowded,
                                                       minimise_cost, PENALTY_START)
from threat_planner.core.optimise.smoothing import check_angles

__all__ = ['CONVERGE_GAIN', 'CONVERGE_RUNS', 'FINAL_EVEN', 'WARM_PENALTY', 'converge',
           'counts_far_threats', 'lower', 'optimiser_cutoff', 'refine', 'usable']

#: Largest (segment, threat) pairs per optimiser evaluation counted in full.
OPTIMISER_DENSE_PAIRS = 4_000
#: The same in a crowded field without flight limits (:func:`counts_far_threats`), and
#: best.SURFACE_DENSE_PAIRS the surface lattice's exact-cost limit there. On 18 random
#: 300-threat fields (1 km box, F 1e9-4e9, w 0.2/0.5/0.8) J over the bench's in-box
#: yardstick went from median 1.0026 / worst 1.0130 (cut-offs) to 1.0005 / 1.0111
#: counting all in the optimiser, and to 1.0005 / 1.0068 with the lattice's 464,000 pairs
#: exact too; 59 -> 77 ms a plan.
OPTIMISER_CROWDED_DENSE_PAIRS = 20_000
#: Optimiser cut-off beyond that, in typical threat spacings.
OPTIMISER_CUTOFF_SPACINGS = 3.0
#: First penalty of a warm replan's rounds (and the winner's last ones), from the previous
#: path as it is: it meets the limits, and a low penalty let the first round leave it and
#: come back elsewhere. The 21 bundled cases after every threat moved 1 mm, warm J at most
#: 1e-6 above a cold plan's: 16 at 10, 18 at 100, 14 at 1000.
WARM_PENALTY = 100.0
#: Even-spacing weight of the last rounds (:func:`converge`), against EVEN_SPACING_WEIGHT
#: before. The spacing term keeps vertices from bunching while the path finds its shape,
#: but it also holds them off J's own optimum, and rounds that stop on a small gain then
#: end anywhere along that slope: uniform20_0 at w 0.8 ended at J 144.98-145.30 with its
#: threats moved 1 nm-1 mm, where SLSQP from those ends found two minima, 144.956 and
#: 144.763; rounds at 0.01 from each end met them to 1e-4 (10 ms), at 1.0 they moved 0.
FINAL_EVEN = 0.01
#: Most runs of those last rounds, each from the last one's end with fresh multipliers,
#: while a run lowered J by more than CONVERGE_GAIN of it. A run ends at its first
#: feasible round that gained little, and from there its L-BFGS stalls in a few
#: iterations (uniform20_1 at w 0.8: 4); a fresh run leaves that point and lands lower
#: (175.0242 -> 175.0233 -> 175.0218 -> 175.0213 in three runs; uniform20_0 at w 0.8
#: 145.0771 -> 144.9655 -> 144.9632 -> 144.9627), where more rounds in one run did not
#: (12 rounds, none stopped on a small gain, tolerance 1e-10: 175.0230, 144.9650). On the
#: 21 bundled cases the step's median went from 0.77 to 2.3 ms (mostly one run more that
#: gains nothing), a plan's from 9.7 to 10.3 ms.
CONVERGE_RUNS = 4
CONVERGE_GAIN = 1e-7


def optimiser_cutoff(segments: int, p: Problem) -> float | None:
    """Cut-off radius for a minimisation over ``segments`` segments, None to count all.

    Every threat is counted while that costs at most OPTIMISER_DENSE_PAIRS pairs per
    evaluation (OPTIMISER_CROWDED_DENSE_PAIRS where :func:`counts_far_threats`). Beyond,
    far threats are dropped: a much wider radius than the edge costs' because the
    optimiser follows the gradient, which a cut-off distorts, into places the Dijkstra
    route never went.
    """
    limit = OPTIMISER_CROWDED_DENSE_PAIRS if counts_far_threats(p) else OPTIMISER_DENSE_PAIRS
    if segments * len(p.threats) <= limit:
        return None
    return OPTIMISER_CUTOFF_SPACINGS * p.threats.typical_spacing(p.box)


def counts_far_threats(p: Problem) -> bool:
    """Whether a crowded field is planned without flight limits: far threats count more.

    Where the reaches exceed the spacing the far threats are a large share of J_R, and
    cut-offs mislead the refinement and the surface routes. Under the limits, counting
    them was measured too (18 random 300-threat fields, the default limits: climb and
    dive 30 deg, turn radius 10 m): 1.7x the time (447 -> 774 ms) with J from -40 % to
    +2 % either way, so they keep the cut-offs.
    """
    return not p.limits.any_constraint and is_crowded(p.threats, p.box)


def converge(p: Problem, best: Candidate) -> Candidate:
    """Return best, or its rounds again at FINAL_EVEN from its own path where lower in J.

    Where the limits bound, the rounds end where a round gained little, short of the
    constrained minimum and wherever rounding leaves them; from there, with the spacing
    held less, they reach the minimum of the basin the path is in (FINAL_EVEN), so a
    plan moves with the input wherever that minimum does. Only where the optimiser counts
    every threat (:func:`optimiser_cutoff`): under a cut-off the rounds lower a J without
    the far threats, and on random 300- and 1,000-threat fields they ran 220-550 L-BFGS
    iterations (45-105 ms, the plan's other rounds 20-35 ms) for no lower J. Up to
    CONVERGE_RUNS runs, each from the last one's end while it gained (CONVERGE_GAIN).
    """
    n = p.config.n_points
    if len(best.final) != n + 1 or optimiser_cutoff(n, p) is not None:
        return best
    for _ in range(CONVERGE_RUNS):
        last, best = best, lower(best, refine(p, best.final, best.seq, best.seed,
                                              tolerance=1e-8, warm=True,
                                              penalty=WARM_PENALTY, even=FINAL_EVEN))
        if last.cost.J - best.cost.J <= CONVERGE_GAIN * abs(best.cost.J):
            break
    return best


def lower(best: Candidate, again: Candidate) -> Candidate:
    """Return `again` (bound, with best's levels if it has none) if usable and lower in J."""
    if usable(again) and again.cost.J < best.cost.J:
        again.limits_bound, again.levels = True, again.levels or best.levels
        return again
    return best


def usable(c: Candidate) -> bool:
    """Whether a candidate meets the limits with a finite J (not through a threat)."""
    return bool(c.limit_check.feasible and np.isfinite(c.cost.J))


def refine(p: Problem, start: NDArray, seq: list[int], name: str,
           tolerance: float = 1e-6, warm: bool = False, box_broken: bool = False,
           gate: Callable[[NDArray], bool] | None = None,
           penalty: float | None = None, respace: bool = False,
           even: float = EVEN_SPACING_WEIGHT, subdivide: bool = False) -> Candidate:
    """Minimise J from a path of n_points segments inside the box and the flight limits.

    Parameters
    ----------
    p : Problem
        The problem.
    start : ndarray
        Starting path, (n+1, 3) [m], from S to T.
    seq : list of int
        Network route reported as the initial path (the line won: the best route).
    name : str
        Seed name reported in PlanResult.seed.
    tolerance : float
        Relative J decrease per iteration below which L-BFGS stops.
    warm : bool
        The start is a previous plan: straight to the constrained rounds if it is feasible.
    box_broken, gate, penalty, respace, even, subdivide
        As :func:`.optimisation.minimise_cost`: the basin's box-only optimum breaks the
        limits; stop at a coarser level (the candidate's path then at its resolution);
        the rounds' first penalty (None: PENALTY_START, WARM_PENALTY for a warm start);
        a warm start evenly resampled first (the rescue's runs) or taken as it is; the
        rounds' even-spacing weight; every level from the coarser one subdivided.

    Returns
    -------
    Candidate

    """
    cfg = p.config
    if penalty is None:
        penalty = WARM_PENALTY if warm else PENALTY_START
    opt = minimise_cost(start, p.threats, cfg.w, p.box if cfg.confine_to_box else None,
                        p.limits, tolerance=tolerance, constrained_only=warm,
                        cutoff=optimiser_cutoff(cfg.n_points, p),
                        box_broken=box_broken, gate=gate, penalty=penalty, respace=respace,
                        even=even, subdivide=subdivide)
    return Candidate(seq=seq, initial=np.vstack([p.s, p.network.nodes[seq], p.t]),
                     smoothed=None, smoothed_cost=None, final=opt.points, k=float('nan'),
                     steps=0, converged=True, cost=p.cost(opt.points),
                     angles=check_angles(opt.points, cfg.max_pitch_deg, cfg.max_turn_deg),
                     seed=name, limit_check=p.check(opt.points),
                     limits_bound=opt.constrained, levels=opt.levels)
