"""How ``best`` tells basins of J apart, ranks them under the slopes, and how far one leads.

Two paths are in one basin when they end within 1 % of the box diagonal of each other,
compared at the coarse screening's resolution. The lead of the chosen basin over the next
distinct one decides warm starts (:mod:`.warm`), and a runner-up refined level by level
stops as soon as it is in the winner's basin or, at the last coarse level, clearly above
it (issue 28: judged at the coarsest level, 10 segments, where J was far from the final
one, or dropped there for breaking a limit, a runner-up that would have won was lost:
n35 seed 1 at w 0.8 of the random fields, 332 against 532 with every threat moved 1 mm).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.methods.problem import Candidate, Problem
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.optimise.optimisation import minimise_cost
from threat_planner.core.optimise.smoothing import resample
from threat_planner.core.world.threats import Box

__all__ = ['COARSE_SEGMENTS', 'COARSE_TOLERANCE', 'RUNNER_UP_MARGIN', 'SCREEN_TIE',
           'SURFACE_DENSE_PAIRS', 'basin_lead', 'known_lead',
           'refined_margin', 'runner_up_gate', 'runner_up_lead', 'same_basin',
           'slope_screening']

#: Segments of the coarse screening, at which basins are compared.
COARSE_SEGMENTS = 8
#: A runner-up basin this much above the best at the last coarse level is not refined
#: further (on the 21 bundled cases, at the coarsest level 12 of 16 runners-up were in the
#: winner's basin and 2 were 22 % and 124 % above it; 2 were refined to the end).
RUNNER_UP_MARGIN = 0.01
#: Stopping tolerance of the coarse screening minimisation (its segments, at which basins
#: are told apart too: COARSE_SEGMENTS).
COARSE_TOLERANCE = 1e-4
#: The surface lattice's exact-cost limit in a crowded field without flight limits
#: (measured beside refining.OPTIMISER_CROWDED_DENSE_PAIRS, see there).
SURFACE_DENSE_PAIRS = 500_000
#: L-BFGS iterations and augmented Lagrangian rounds of the slope-held screening (a
#: ranking: measured against 200 and 6 on the 21 bundled cases, 15 % less time, final J
#: within 0.04 % either way).
SLOPE_SCREEN_ITERATIONS = 40
SLOPE_SCREEN_ROUNDS = 3
#: Largest breach of a slope (or altitude) limit [deg] ([m]) that a screened seed may end
#: with and still rank by its J: the refinement meets the limits exactly. Three rounds end
#: a few tenths of a degree over the limit or under it as rounding has it (uniform20_1 at w
#: 0.811, max climb 24 deg: the 178 basins ended 0.04-0.33 deg over, ranked after the
#: feasible 250 ones, and the plan came out at 241 against 177 at 23 and 176 at 25 deg).
SLOPE_SCREEN_SLACK = 1.0
#: Slope-held seeds whose screening J is within this fraction of the best one's are ties
#: at 8 segments: method best refines each as a gated runner-up after the usual basins,
#: unless in the basin of one refined already (outside crowded fields). On bench
#: perturbation's 66 cases the winners found so sat 2.0 % and 3.8 % above the best held J
#: and refined 5.2 % and 3.0 % lower (n35 seed 2 w 0.5, n35 seed 1 w 0.8); the 21 bundled
#: cases with the limits on, unchanged, took 2 % more time in all. Every seed in reach (10
#: of the ranking) also found uniform20_0 at w 0.8 0.18 % lower (held 11 % above) for
#: +86 %.
SCREEN_TIE = 0.05


def basin_lead(p: Problem, ranked: list[tuple[float, NDArray]]) -> float:
    """Relative J lead of the first of ``ranked`` (J, path) over the next distinct basin.

    Paths that end within 1 % of the box diagonal of the first are the same basin; paths
    are compared at the coarse resolution (surface routes have their own point counts).
    No distinct runner-up: an infinite lead.
    """
    j0, first = ranked[0]
    for j_other, other in ranked[1:]:
        if not same_basin(p, first, other):
            return j_other / j0 - 1.0 if j0 > 0 else 0.0
    return float('inf')


def runner_up_gate(p: Problem, answers: tuple, verdict: list) -> Callable[[NDArray], bool]:
    """Return the refine gate of a runner-up against best's answers level by level.

    It stops the runner-up at a level (its warm-start lead appended to ``verdict``) as
    soon as :func:`runner_up_lead` tells, against best's answer at the same level.
    """
    mine = {len(a): a for a in answers}
    last = max(mine, default=0)

    def gate(points: NDArray) -> bool:
        lead = None if len(points) not in mine else runner_up_lead(
            p, mine[len(points)], points, p.check(points).feasible, len(points) == last)
        if lead is not None:
            verdict.append(lead)
        return lead is not None
    return gate


def runner_up_lead(p: Problem, mine: NDArray, theirs: NDArray, feasible: bool,
                   last: bool = True) -> float | None:
    """Decide on a runner-up at a coarse level: None to refine it further.

    ``mine`` is best's answer and ``theirs`` the runner-up's at the same level, ``last``
    whether it is the last coarse level. Otherwise the warm-start lead it leaves best:
    infinite when it is in best's basin there (no rival: it caps nothing), else, at the
    last coarse level and meeting the limits, its relative J excess when that is more
    than RUNNER_UP_MARGIN. One that breaks the limits at a coarse level is refined on (the
    finer levels met them for it: n35 seed 1 at w 0.8, J 332).
    """
    if same_basin(p, mine, theirs):
        return float('inf')
    if not (feasible and last):
        return None
    j_best, j_part = p.cost(mine).J, p.cost(theirs).J
    if j_part > (1.0 + RUNNER_UP_MARGIN) * j_best:
        return j_part / j_best - 1.0
    return None


def same_basin(p: Problem, a: NDArray, b: NDArray, resampled: bool = False) -> bool:
    """Whether two paths lie within 1 % of the box diagonal (compared at 8 segments).

    ``resampled``: both are already resampled to COARSE_SEGMENTS.
    """
    gap = a - b if resampled else resample(a, COARSE_SEGMENTS) - resample(b, COARSE_SEGMENTS)
    return float(np.max(np.einsum('ij,ij->i', gap, gap))) <= (0.01 * p.box.diagonal) ** 2


def refined_margin(p: Problem, best: Candidate, refined: list[Candidate],
                   held_margin: float) -> float:
    """Return the warm-start lead of best where the limits bound: 0 unless it is feasible.

    The lead under the slope limits of the screening (``held_margin``), and no more than
    the lead over the next distinct basin refined under all the limits (none refined: the
    screening's lead; :mod:`.warm` asks for a lead in proportion to the move, so a small
    move replans warm and a 0.5 % move asks for 1 %).
    """
    if not best.limit_check.feasible or best.cost.J <= 0:
        return 0.0
    others = [(c.cost.J, c.final) for c in refined
              if c is not best and c.limit_check.feasible]
    return known_lead(held_margin, basin_lead(p, [(best.cost.J, best.final)]
                                              + sorted(others, key=lambda o: o[0])))


def known_lead(held: float, rival: float) -> float:
    """Return the warm-start lead from the screening's (``held``) and a refined rival's.

    ``held`` NaN is not known (no seed met the slopes), inf every seed in one basin;
    ``rival`` inf is no distinct rival refined. The least finite one (at least 0), else
    inf where the screening saw one basin, else 0: nothing known, no warm start (on 400
    random fields of test_stable_plans, capping a rival's 87 % lead by an unknown
    screening lead of 0 sent 3 replans cold that then jumped 1-51 %).
    """
    known = [x for x in (held, rival) if np.isfinite(x)]
    if known:
        return max(min(known), 0.0)
    return float('inf') if held == float('inf') else 0.0


def slope_screening(p: Problem, screened: list, bounds: Box | None, cutoff: float | None,
                    optimal: set[str], tolerance: float) -> tuple[list[tuple], float, list]:
    """Rank the screened seeds again, held to the climb and dive limits, best first.

    The slope limits mean the same at 8 segments as at n_points (the turn radius does
    not: 8 segments cannot turn on a 10 m circle), so this ranks the basins as flown: a
    limit-free basin that climbs a wall may lose to one that does not. Seeds the coarse
    run could not bring within the slopes rank last. Returns the ranking, the lead of its
    best basin over the next distinct one (:func:`basin_lead`; NaN, not known, when no
    seed met the slopes within SLOPE_SCREEN_SLACK), and the ranked seeds tied with its
    first (held J within SCREEN_TIE of the first's; none where that is infinite: every
    other would tie with a seed through a threat). ``tolerance`` is the screening's
    stopping tolerance.

    Seeds named in ``optimal`` are box-only optima already, whose J holding the slopes
    can only rise from: one whose J is already at least the second-best held J cannot
    rank in the first two, and is left out (on the 21 bundled cases: 12 % fewer L-BFGS
    runs in all, J within 0.001 %).
    """
    lim = p.limits
    slopes = FlightLimits(lim.max_climb_deg, lim.max_dive_deg, 0.0, lim.min_altitude_m)
    floor = float(p.box.lo[2])
    # Every distinct seed: re-screening only the best 4 lost 10 % J on uniform20_1 at
    # w = 0.8. A seed that screened into the basin of a better-ranked one would repeat
    # its run; the others run surface routes (not minimised yet) first.
    kept: list[NDArray] = []
    todo = []
    for j_box, name, seq, coarse in screened:
        key = resample(coarse, COARSE_SEGMENTS)
        if not any(same_basin(p, key, k, resampled=True) for k in kept):
            kept.append(key)
            todo.append((name in optimal, j_box, name, seq, key))
    todo.sort(key=lambda item: item[0])
    held, skipped = [], []
    for bounded, j_box, name, seq, start in todo:
        done = sorted(item[1] for item in held if not item[0])
        if bounded and len(done) >= 2 and j_box >= done[1]:
            skipped.append(j_box)
            continue
        res = minimise_cost(start, p.threats, p.config.w, bounds, slopes, cutoff=cutoff,
                            constrained_iterations=SLOPE_SCREEN_ITERATIONS,
                            constrained_rounds=SLOPE_SCREEN_ROUNDS,
                            tolerance=tolerance)
        j = p.cost(res.points).J
        # Through a threat (J inf: a line the minimiser cannot move off) ranks last too.
        breach = check_limits(res.points, slopes, floor).violations
        ok = max(breach.values(), default=0.0) <= SLOPE_SCREEN_SLACK and np.isfinite(j)
        held.append((not ok, j, f'{name} (slopes held)', seq, res.points, res.constrained))
    held.sort(key=lambda item: item[:2])
    feasible = [(item[1], item[4]) for item in held if not item[0]]
    lead = basin_lead(p, feasible) if feasible else float('nan')
    if feasible and skipped and feasible[0][0] > 0:
        # A left-out seed may be the next distinct basin: its J bounds the lead.
        lead = min(lead, min(skipped) / feasible[0][0] - 1.0)
    first = held[0][1] if held else np.inf
    ties = [item[2:] for item in held if item[1] <= (1.0 + SCREEN_TIE) * first] \
        if np.isfinite(first) else []
    return [item[2:] for item in held], lead, ties
