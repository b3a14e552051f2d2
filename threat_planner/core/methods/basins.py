"""How ``best`` tells basins of J apart and how far its chosen one leads the next.

Two paths are in one basin when they end within 1 % of the box diagonal of each other,
compared at the coarse screening's resolution. The lead of the chosen basin over the next
distinct one decides warm starts (:mod:`.warm`), and a runner-up refined level by level
stops as soon as it is in the winner's basin or clearly above it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.methods.problem import Candidate, Problem
from threat_planner.core.optimise.smoothing import resample

__all__ = ['COARSE_SEGMENTS', 'RUNNER_UP_MARGIN', 'basin_lead', 'refined_margin', 'runner_up_gate',
           'runner_up_lead', 'same_basin']

#: Segments of the coarse screening, at which basins are compared.
COARSE_SEGMENTS = 8
#: A runner-up basin this much above the best at a coarse level is not refined further
#: (on the 21 bundled cases, at the coarsest level 12 of 16 runners-up were in the winner's
#: basin and 2 were 22 % and 124 % above it; 2 were refined to the end).
RUNNER_UP_MARGIN = 0.01


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
    soon as :func:`_runner_up_lead` tells, against best's answer at the same level.
    """
    mine = {len(a): a for a in answers}

    def gate(points: NDArray) -> bool:
        lead = None if len(points) not in mine else runner_up_lead(
            p, mine[len(points)], points, p.check(points).feasible)
        if lead is not None:
            verdict.append(lead)
        return lead is not None
    return gate


def runner_up_lead(p: Problem, mine: NDArray, theirs: NDArray, feasible: bool
                   ) -> float | None:
    """Decide on a runner-up at a coarse level: None to refine it further.

    ``mine`` is best's answer and ``theirs`` the runner-up's at the same level. Otherwise
    the warm-start lead it leaves best: 0 when it is in best's basin there or breaks the
    limits (no distinct feasible rival known, as :func:`_refined_margin`), else its
    relative J excess when that is more than RUNNER_UP_MARGIN.
    """
    if same_basin(p, mine, theirs) or not feasible:
        return 0.0
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
    the lead over the next distinct basin refined under all the limits: none refined, no
    lead (measured: where the refined starts all ended in one basin, a cold replan after
    a 0.5 % move found another 2.4 % lower on uniform20_0 at w = 0.5).
    """
    if not best.limit_check.feasible or best.cost.J <= 0:
        return 0.0
    others = [(c.cost.J, c.final) for c in refined
              if c is not best and c.limit_check.feasible]
    lead = basin_lead(p, [(best.cost.J, best.final)] + sorted(others, key=lambda o: o[0]))
    return max(min(held_margin, lead), 0.0) if np.isfinite(lead) else 0.0
