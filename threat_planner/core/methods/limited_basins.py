"""Limited basins method ``best`` adds once the limits are on: never above its winner.

The cold refinement holds the flight limits from its coarse levels on and ranks the basins
by a slope-held screening at 8 segments; both can miss the limited optimum (issue 42's
limited yardstick found paths 4-7 % below on fresh fields). Two additions run after the
winner is converged, each kept only where it ends lower: lattice routes refined as
runners-up (:func:`lattice_basins`: the volume lattice's where a limit bound the winner,
the slope-limited surface lattice's always), and the best box-only basins refined from
their limit-free optimum at full resolution (:func:`free_first`; with the volume routes'
where no limit bound the winner, which then was the only basin refined).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.methods.basins import (COARSE_SEGMENTS, COARSE_TOLERANCE, same_basin,
                                                slope_screening, SURFACE_DENSE_PAIRS)
from threat_planner.core.methods.problem import Candidate, Problem
from threat_planner.core.methods.refining import (converge, counts_far_threats,
                                                  optimiser_cutoff, refine, usable)
from threat_planner.core.network.seeds import sloped_routes, volume_routes
from threat_planner.core.optimise.optimisation import minimise_cost, PENALTY_START
from threat_planner.core.optimise.smoothing import resample

__all__ = ['FREE_FIRST_BASINS', 'FREE_FIRST_CONVERGE', 'FREE_FIRST_LOOKS',
           'LIMITED_BASINS_MAX_THREATS', 'free_first', 'lattice_basins', 'sloped_lines',
           'SLOPED_ROUTES', 'volume_lines']

#: Largest field where, once the limits are on, the lattice routes and the limit-free
#: optima are tried too (:func:`lattice_basins`, :func:`free_first`). Measured on the
#: gate's fresh seed 1796647071: at 1,000-3,000 threats they lowered 10 of 60 plans by up
#: to 7.7 % for 1.7x the time; at 10,000 they cost 1.0 s a plan and lowered none.
LIMITED_BASINS_MAX_THREATS = 3000
#: Distinct limit-free optima refined under the limits (:func:`free_first`). On that seed's
#: 90 limited cases (20-300 threats) 2 and 3 found the same plans but one (0.02 %).
FREE_FIRST_BASINS = 2
#: Box-only screened basins (distinct at the coarse resolution) minimised in the box alone
#: in search of those: several screen into one limit-free optimum (clustered n300 f1 w 0.8
#: of seed 1796664513: the first, second and fifth into 178.35), and the limited optimum
#: came from the third distinct one (266.71 under the limits, the others 323.7-348.0).
#: 4 and 6 found the same plans on that seed's 90 limited cases.
FREE_FIRST_LOOKS = 4
#: Slope-limited surface routes refined (:func:`sloped_lines`); on the fields of
#: :func:`lattice_basins` the third of three found the 1,000-threat one.
SLOPED_ROUTES = 3
#: Such a candidate is converged when within this fraction of best's J (a converge
#: lowered one from 341.6 to 327.6, below the 338.7 that had won).
FREE_FIRST_CONVERGE = 0.05


def volume_lines(p: Problem) -> list[tuple[float, str, list, NDArray]]:
    """Return the volume lattice's routes as screened entries ``(J, name, [], line)``."""
    return _entries(p, 'volume route', volume_routes(p.threats, p.s, p.t, p.box, p.config.w,
                                                     dense_pairs=_dense(p)))


def sloped_lines(p: Problem) -> list[tuple[float, str, list, NDArray]]:
    """Return the slope-limited surface routes as screened entries (none without slopes).

    SLOPED_ROUTES of :func:`..network.seeds.sloped_routes` at the stricter of the climb
    and dive limits.
    """
    lim = p.limits
    if not (lim.climb_on or lim.dive_on):
        return []
    return _entries(p, 'sloped route', sloped_routes(
        p.threats, p.s, p.t, p.box, p.config.w, min(lim.max_climb_deg, lim.max_dive_deg),
        count=SLOPED_ROUTES, dense_pairs=_dense(p)))


def _dense(p: Problem) -> int | None:
    """Return the pairs the lattices cost exactly (more where the far threats count)."""
    return SURFACE_DENSE_PAIRS if counts_far_threats(p) else None


def _entries(p: Problem, kind: str, lines: list[NDArray]) -> list[tuple]:
    """Return lattice routes as screened entries ``(J, 'kind i', [], line)``, least J first."""
    return sorted(((p.cost(line).J, f'{kind} {i}', [], line) for i, line in enumerate(lines)),
                  key=lambda e: e[0])


def lattice_basins(p: Problem, best: Candidate, refined: list[Candidate], route: list[int],
                   cutoff: float | None, refine_seed: Callable, screened: list) -> Candidate:
    """Return best, or a lower one refined from lattice routes (limits on).

    Screened with the others, the volume routes displaced basins that had won (a fresh
    3,000-threat plan 0.6 % higher); here they and the sloped routes (``screened``:
    :func:`volume_lines`, :func:`sloped_lines`) are slope-held screened on their own and
    refined as gated runners-up (``refine_seed``: best's) after best is known, so they
    only add. On the gate's seed 1796647071 the volume routes found coplanar n100 f0 w 0.8
    6.4 % lower and strongweak n300 f1 w 0.5 3.8 % lower (the limited yardstick's 377.39:
    377.54); the sloped ones found uniform n300 f0 w 0.8 of seed 1796664513 8.3 % lower
    (407.77 -> 373.89, the yardstick 406.29).
    """
    if not screened:
        return best
    if p.limits.climb_on or p.limits.dive_on:
        entries, _, _ = slope_screening(p, screened, p.box, cutoff, set(), COARSE_TOLERANCE)
    else:
        entries = [(name, seq, line, False) for _, name, seq, line in screened]
    for entry in entries:
        if any(same_basin(p, entry[2], c.final) for c in refined if usable(c)):
            continue
        cand, _ = refine_seed(p, entry, route, best, True)
        if cand is None or not usable(cand):
            continue
        refined.append(cand)
        if cand.cost.J < best.cost.J:
            cand = converge(p, cand)
            if cand.cost.J < best.cost.J:
                best = cand
    return best


def free_first(p: Problem, best: Candidate, screened: list, lattice: list = ()) -> Candidate:
    """Return best, or a lower one refined from a basin's limit-free optimum (limits on).

    The cold refinement holds the limits from its coarse levels on, and can end in another
    limited basin than the one next to the limit-free optimum: on uniform n100 f0 w 0.8 of
    seed 1796647071 it ended at 338.71, the limited yardstick (SLSQP from its grid routes)
    at 316.75. Up to FREE_FIRST_LOOKS distinct box-only screened basins are minimised
    within the box alone at n_points, and the first FREE_FIRST_BASINS distinct optima are
    held to the limits from there by the rounds alone, at n_points, from the cold first
    penalty (PENALTY_START): 314.55 from the second basin. A warm replan's penalty
    (WARM_PENALTY) holds the nearest limited path to an optimum that breaks the limits
    wide: on uniform n300 f0 w 0.8 of seed 1796664513 it kept a floor-hugging path with a
    zigzag climb at the goal (425.61), from PENALTY_START the rounds climbed along the way
    (407.77; the limited yardstick 406.29). An optimum already at best's J is skipped:
    its limited one lies above. Each of the ``lattice`` entries (:func:`volume_lines`,
    given where no limit bound best) is looked at after those, in a basin not looked at
    already.
    """
    looks = _Looks(p)
    for entry in screened:
        if len(looks.optima) >= FREE_FIRST_BASINS or len(looks.picked) >= FREE_FIRST_LOOKS:
            break
        best = looks.look(best, *entry)
    for entry in lattice:
        best = looks.look(best, *entry)
    return best


class _Looks:
    """The basins :func:`free_first` looked at and the distinct limit-free optima found."""

    def __init__(self, p: Problem) -> None:
        self.p, self.n = p, p.config.n_points
        self.cutoff = optimiser_cutoff(self.n, p)
        self.picked: list[NDArray] = []
        self.optima: list[NDArray] = []

    def look(self, best: Candidate, j: float, name: str, seq: list[int], coarse: NDArray
             ) -> Candidate:
        """Return best, or the lower limited path from this seed's limit-free optimum."""
        p, n = self.p, self.n
        key = resample(coarse, COARSE_SEGMENTS)
        if not np.isfinite(j) or any(same_basin(p, key, k, resampled=True)
                                     for k in self.picked):
            return best
        self.picked.append(key)
        free = minimise_cost(resample(coarse, n), p.threats, p.config.w, p.box,
                             cutoff=self.cutoff).points
        if any(same_basin(p, free, k) for k in self.optima):
            return best
        self.optima.append(free)
        if not p.cost(free).J < best.cost.J:
            return best
        cand = refine(p, free, seq, f'{name}, from its limit-free optimum', warm=True,
                      penalty=PENALTY_START)
        if usable(cand) and cand.cost.J < (1.0 + FREE_FIRST_CONVERGE) * best.cost.J:
            cand = converge(p, cand)
            if cand.cost.J < best.cost.J:
                cand.limits_bound = True
                return cand
        return best
