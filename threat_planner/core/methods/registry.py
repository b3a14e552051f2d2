"""The planner's three methods, each a function of one planning problem.

* ``paper``: the paper as written: length-weighted Dijkstra from the node nearest the start
  to the node nearest the goal, mass-spring smoothing at a fixed k, angle check.
* ``improved``: the paper's Cases 1-3 together: Dijkstra on each edge's J (Case 2) for every
  pair of K entry and exit nodes spread around S and T as in Fig. 11 (Case 1), the pair of
  least final J kept, then k swept over 500..3000 step 100 for least J among angle-feasible
  paths (Case 3).
* ``best`` (:mod:`.best`): distinct J-weighted routes, the straight line and box surface
  routes screened by a coarse minimisation of J, the winners refined on J itself within
  the box and the physical flight limits.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from threat_planner.core.methods.best import plan_best
from threat_planner.core.methods.problem import Candidate, Problem, smooth_route
from threat_planner.core.network.search import dijkstra_pairs, entry_candidates, nearest_nodes

__all__ = ['METHOD_FUNCTIONS', 'K_SWEEP']

#: Case 3's k sweep, from the paper: 500 <= k <= 3000 in steps of 100.
K_SWEEP = tuple(range(500, 3001, 100))


def _sweep_k(p: Problem, best: Candidate) -> Candidate:
    """Case 3: the least-J angle-feasible smoothing of best's route over K_SWEEP."""
    feasible_best = best if best.angles.feasible else None
    done = len(p.candidates)
    for n_done, k in enumerate(K_SWEEP, 1):
        cand = smooth_route(p, best.seq, float(k))
        p.k_sweep[float(k)] = cand.cost.J if cand.angles.feasible else float('inf')
        if cand.angles.feasible and (feasible_best is None
                                     or cand.cost.J < feasible_best.cost.J):
            feasible_best = cand
        if p.progress:
            p.progress(done + n_done, done + len(K_SWEEP))
    p.clock.lap('k_sweep_ms')
    return feasible_best or best


def plan_paper(p: Problem) -> Candidate:
    """Length-weighted Dijkstra between the nodes nearest S and T, smoothed at k."""
    entry = int(nearest_nodes(p.network, p.s, 1)[0])
    exit_ = int(nearest_nodes(p.network, p.t, 1)[0])
    seq = dijkstra_pairs(p.network, p.network.edge_lengths, np.array([entry]),
                         np.array([exit_]))
    p.clock.lap('search_ms')
    p.route_found(seq[(entry, exit_)][0])
    best = smooth_route(p, seq[(entry, exit_)][0], p.config.k)
    p.clock.lap('smoothing_ms')
    return _sweep_k(p, best) if p.config.auto_k else best


def plan_improved(p: Problem) -> Candidate:
    """Cases 1-3: J-weighted Dijkstra per entry/exit pair, least J kept, then the k sweep."""
    cfg = p.config
    entries = entry_candidates(p.network, p.s, p.t, cfg.entry_candidates, cfg.candidates)
    exits = entry_candidates(p.network, p.t, p.s, cfg.entry_candidates, cfg.candidates)
    routes = dijkstra_pairs(p.network, p.edge_j.weights(p.network.edge_lengths, cfg.w),
                            entries, exits)
    p.clock.lap('search_ms')
    if routes:
        p.route_found(min(routes.values(), key=lambda route: route[1])[0])
    best = None
    for n_done, (pair, (seq, _)) in enumerate(routes.items(), 1):
        cand = smooth_route(p, seq, cfg.k)
        p.candidates[pair] = cand.cost.J
        if best is None or cand.cost.J < best.cost.J:
            best = cand
        if p.progress:
            p.progress(n_done, len(routes) + len(K_SWEEP))
    p.clock.lap('smoothing_ms')
    return _sweep_k(p, best)


#: Method name -> the function that solves a Problem with it.
METHOD_FUNCTIONS: dict[str, Callable[[Problem], Candidate]] = {
    'paper': plan_paper, 'improved': plan_improved, 'best': plan_best}
