"""cost_model 'detection': the plan of least w H + (1 - w) L / L_0, or the shortest within a bound.

Method ``best`` plans first on the paper's J (its routes, screening and refinement under
the flight limits, or its airspace method among zones and terrain): that plan meets the
limits, passes the threats on its own sides, and starts the minimisation of the detection
objective, so the detection plan's objective is never above it. Beside it the straight
line and the distinct network routes are screened on the detection objective at
``COARSE_SEGMENTS`` segments (box only) and the best ``REFINED`` of them refined at the
plan's own segments under the limits (:mod:`.optimise`); the feasible one of least exact
objective wins.

With ``max_detection`` P < 1 the plan is the shortest path with P_detect <= P: the same
search on the near-pure hazard (weight ``LEAST_HAZARD_W``) finds the least P_detect within
the limits; where that is above P the plan says so (``detection_status``) and returns it;
else the length is minimised under H <= -ln(1 - P) from there (and from any start that
meets the bound already). No-fly zones stay hard: a minimisation that enters one is drawn
back towards its start to where it is clear.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.detection.model import DetectionModel
from threat_planner.core.detection.optimise import (DetectionProblem, minimise_detection,
                                                    Outcome, refine_slsqp)
from threat_planner.core.methods.best import network_routes, plan_best
from threat_planner.core.methods.problem import Candidate, Problem
from threat_planner.core.optimise.limits import FlightLimits
from threat_planner.core.optimise.smoothing import check_angles, resample

__all__ = ['plan_detection', 'replan_detection']

#: Segments of the screening minimisation.
COARSE_SEGMENTS = 10
#: Screened basins refined under the limits (the paper-cost plan's among the screened).
REFINED = 3
#: Segments of the middle level of the refinement, and SLSQP iterations at the finest.
MIDDLE_SEGMENTS = 20
FINE_ITER = 100
#: L-BFGS-B iterations of a screening minimisation.
SCREEN_ITER = 100
#: Screened answers apart by less than this fraction of L_0 at every vertex share a basin.
SAME_BASIN = 0.02
#: Weight of H when looking for the least P_detect within the limits (the length only
#: breaks ties between paths of equal hazard).
LEAST_HAZARD_W = 1.0 - 1e-4
#: Bisection steps drawing a path that entered a zone back towards its start.
ZONE_BISECTIONS = 20


def plan_detection(p: Problem) -> Candidate:
    """Plan with cost_model 'detection' (see the module docstring)."""
    if p.airspace is not None:
        from threat_planner.core.methods.in_airspace import plan_in_airspace
        paper = plan_in_airspace(p)
    else:
        paper = plan_best(p)
    cfg = p.config
    prob = _problem(p)
    seeds = _seeds(p, paper)
    bound = cfg.max_detection < 1.0
    if not bound:
        out, lead = _search(p, prob, paper.final, seeds)
        p.clock.lap('detection_ms')
        return _candidate(p, paper, out, '', lead)
    h_max = -math.log1p(-cfg.max_detection)
    least, lead = _search(p, dataclasses.replace(prob, w=LEAST_HAZARD_W), paper.final,
                          seeds)
    if least.hazard > h_max:
        p.clock.lap('detection_ms')
        status = (f'unmet: the least P_detect found within the limits is '
                  f'{-math.expm1(-least.hazard):.6g} > max_detection {cfg.max_detection:g}')
        return _candidate(p, paper, least, status, lead,
                          bounded=dataclasses.replace(prob, h_max=h_max))
    bounded = dataclasses.replace(prob, h_max=h_max)
    starts = [least.points]
    for start in (paper.final, resample(np.vstack([p.s, p.t]), cfg.n_points)):
        if bounded.feasible(start):
            starts.append(start)
    best = None
    for start in starts:
        # The augmented Lagrangian, not SLSQP: from the least-hazard path SLSQP stopped
        # far inside the bound (uniform20_0, P <= 0.05: P 0.0295 at L 147.4 against the
        # rounds' P 0.05 at L 144.1).
        out = _clear(p, paper.final, minimise_detection(start, bounded), bounded)
        if out.feasible and (best is None or out.objective < best.objective):
            best = out
    if best is None:   # the least-hazard path itself meets the bound
        best = Outcome(least.points, least.hazard, bounded.objective(least.points), True, 0, 0)
    p.clock.lap('detection_ms')
    return _candidate(p, paper, best, 'met', lead, bounded=bounded)


def replan_detection(p: Problem, path: NDArray, previous: object) -> Candidate | None:
    """Refine a warm replan's path on the detection objective, or None to plan cold.

    The path is :mod:`threat_planner.core.methods.warm`'s: SLSQP at the plan's segments,
    the rounds where it stops short; None where the result breaks a limit or the bound.

    The warm rule's basin lead is the detection basins' (:func:`_search` sets it), so a
    move that could swap them plans cold.
    """
    cfg = p.config
    prob = _problem(p)
    bounded = cfg.max_detection < 1.0
    if bounded:
        prob = dataclasses.replace(prob, h_max=-math.log1p(-cfg.max_detection))
    out = refine_slsqp(path, prob, max_iter=FINE_ITER, layouts=2)
    if not out.feasible:
        out = minimise_detection(out.points, prob)
    h = prob.hazard(path)
    if prob.feasible(path, h) and (not out.feasible or prob.objective(path, h) <= out.objective):
        out = Outcome(path, h, prob.objective(path, h), True, 0, 0)
    if not out.feasible:
        return None
    points = out.points
    return Candidate(seq=list(previous.node_sequence), initial=previous.initial_path,
                     smoothed=None, smoothed_cost=None, final=points, k=float('nan'),
                     steps=0, converged=True, cost=p.cost(points),
                     angles=check_angles(points, cfg.max_pitch_deg, cfg.max_turn_deg),
                     seed=previous.seed, limit_check=p.check(points),
                     basin_margin=previous.basin_margin, limits_bound=True,
                     objective=out.objective,
                     detection_status='met' if bounded else '')


def _problem(p: Problem) -> DetectionProblem:
    cfg, box = p.config, p.box
    lo, hi = box.lo.astype(float).copy(), box.hi.astype(float).copy()
    if not cfg.confine_to_box:
        lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
        lo[2] = float(box.lo[2])
    lo[2] = min(lo[2] + cfg.min_altitude_m, float(box.hi[2]))
    pieces_of = None
    if p.airspace is not None and p.airspace.masking:
        from functools import partial
        from threat_planner.core.cost.masking import visible_pieces
        pieces_of = partial(_seen, visible_pieces, p.threats.positions, p.airspace.terrain)
    return DetectionProblem(positions=p.threats.positions, intensities=p.threats.intensities,
                            model=DetectionModel.of(cfg), w=cfg.w,
                            l0=max(float(np.linalg.norm(p.t - p.s)), 1e-9), lo=lo, hi=hi,
                            limits=p.limits, floor_z=float(box.lo[2]), pieces_of=pieces_of)


def _seen(visible_pieces, positions: NDArray, terrain, points: NDArray) -> tuple:
    """Return the pieces of a path's segments each radar sees over the terrain."""
    return visible_pieces(points, positions, terrain)


def _seeds(p: Problem, paper: Candidate) -> list[NDArray]:
    """Return the straight line and the distinct network routes, as polylines."""
    seeds = [np.vstack([p.s, p.t])]
    if p.airspace is None and p.edge_j is not None:
        nodes = p.network.nodes
        seeds += [np.vstack([p.s, nodes[seq], p.t]) for seq in network_routes(p)]
    return seeds


def _search(p: Problem, prob: DetectionProblem, paper: NDArray, seeds: list[NDArray]
            ) -> tuple[Outcome, float]:
    """Screen the seeds coarsely, refine the paper plan and the best screened other basins.

    A screened answer within ``SAME_BASIN`` of L_0 of one ranked above it (every vertex,
    at equal arc-length steps) is that basin again and is not refined. Returns the best
    feasible outcome and the screening's lead of the best basin over the next distinct
    one (relative; inf where every seed screened into one basin): the warm rule's margin.
    """
    free = dataclasses.replace(prob, limits=FlightLimits())
    screened = []
    for seed in [paper, *seeds]:
        coarse = resample(seed, COARSE_SEGMENTS)
        out = minimise_detection(coarse, free, rounds=1, max_iter=SCREEN_ITER)
        screened.append((out.objective, out.points))
    screened.sort(key=lambda item: item[0])
    n = p.config.n_points
    starts, basins, values = [], [], []
    for value, points in screened:
        if _in_basin(points, basins, prob.l0):
            continue
        basins.append(points)
        values.append(value)
        if len(starts) < REFINED:
            starts.append(points)
    if p.airspace is not None:
        # The screening knows no zones: its basins may cross one, and be drawn back to
        # the paper-cost plan whole; refined from that plan itself, the path stays near it.
        starts.insert(0, paper)
    h = prob.hazard(paper)
    # The paper-cost plan meets the limits: the detection plan is never above it.
    best = Outcome(paper, h, prob.objective(paper, h), prob.feasible(paper, h), 0, 0)
    middles: list[NDArray] = []
    ends = []
    for start in starts:
        out = _refine(start, prob, n, middles)
        if out is None:
            continue
        out = _clear(p, paper, out, prob)
        if out.feasible and not _in_basin(out.points, [other for _, other in ends],
                                          prob.l0):
            ends.append((out.objective, out.points))
        if out.feasible and (not best.feasible or out.objective < best.objective):
            best = out
    # The lead over the next distinct basin: refined where two were, else screened.
    ends = sorted(value for value, _ in ends)
    if len(ends) > 1 and ends[0] > 0:
        lead = ends[1] / ends[0] - 1.0
    else:
        lead = values[len(starts)] / values[0] - 1.0 if len(values) > len(starts) and \
            values[0] > 0 else math.inf
    return best, lead


def _in_basin(points: NDArray, others: list[NDArray], l0: float) -> bool:
    """Whether a path lies within SAME_BASIN of L_0 of one of others at every vertex."""
    return any(np.max(np.linalg.norm(points - other, axis=1)) < SAME_BASIN * l0
               for other in others)


def _refine(points: NDArray, prob: DetectionProblem, n: int,
            middles: list[NDArray] | None = None) -> Outcome | None:
    """SLSQP under the limits at MIDDLE_SEGMENTS (where fewer than n), then at n segments.

    The QP of SLSQP grows as the cube of the vertices: most of the shape is found at the
    middle level, where an iteration costs a fraction of one at n. A middle answer in the
    basin of one refined before (``middles``, SAME_BASIN) goes no further: on uniform20_0
    three screened basins met at the middle level and ended within 1e-7 of each other.
    Returns None for such an answer.
    """
    if MIDDLE_SEGMENTS < n and len(points) - 1 < MIDDLE_SEGMENTS:
        out = refine_slsqp(resample(points, MIDDLE_SEGMENTS), prob, layouts=2)
        if middles is not None:
            if out.feasible and _in_basin(out.points, middles, prob.l0):
                return None
            middles.append(out.points)
        points = out.points
    out = refine_slsqp(resample(points, n), prob, max_iter=FINE_ITER, layouts=2)
    if not out.feasible:
        # SLSQP's iterates meet the constraints only at its end: where it stopped short,
        # the augmented Lagrangian's rounds take its last iterate to a feasible one.
        out = minimise_detection(out.points, prob)
    return out


def _clear(p: Problem, anchor: NDArray, out: Outcome, prob: DetectionProblem) -> Outcome:
    """Return out, or where it enters a no-fly zone or the terrain, the clear path nearest it.

    The anchor is the paper-cost plan, clear of every zone: the path is drawn back along
    the straight blend towards it (both at the same arc-length steps) to the last point
    where every segment is clear and the limits hold.
    """
    air = p.airspace
    if air is None or not out.feasible:
        return out

    def ok(points: NDArray) -> bool:
        return bool(np.all(air.segment_ok(points[:-1], points[1:]))) and prob.feasible(points)
    if ok(out.points):
        return out
    n = len(out.points) - 1
    start, end = resample(anchor, n), resample(out.points, n)
    if not ok(start):
        return dataclasses.replace(out, feasible=False)
    lo, hi = 0.0, 1.0
    for _ in range(ZONE_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if ok(start + mid * (end - start)):
            lo = mid
        else:
            hi = mid
    points = start + lo * (end - start)
    h = prob.hazard(points)
    return Outcome(points, h, prob.objective(points, h), True, out.rounds, out.evaluations)


def _candidate(p: Problem, paper: Candidate, out: Outcome, status: str, lead: float,
               bounded: DetectionProblem | None = None) -> Candidate:
    cfg = p.config
    points = out.points
    objective = out.objective if bounded is None else bounded.objective(points)
    return dataclasses.replace(
        paper, final=points, smoothed=None, smoothed_cost=None, k=float('nan'), steps=0,
        converged=True, cost=p.cost(points),
        angles=check_angles(points, cfg.max_pitch_deg, cfg.max_turn_deg),
        seed=f'{paper.seed}, detection', limit_check=p.check(points), objective=objective,
        detection_status=status, basin_margin=lead)
