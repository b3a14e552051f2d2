"""In-box yardsticks for the benchmark: slow, careful least-J paths inside the flight box.

``test/data/reference.json`` was refined without bounds, so its paths leave the box and it
is only a lower bound. The yardsticks here play by the box's rules and score every path with
the library's exact closed form (:func:`threat_planner.core.cost.closed_form.path_cost`):

* :func:`in_box_yardstick` (no flight limits): a ``grid``^3 26-connected grid over the box
  (:func:`bench.toolkit.grid.build_grid`, exact J of every edge), Dijkstra for ``routes``
  alternative routes (the edges of earlier routes penalised x ``penalty``) plus the straight
  line; each is resampled to ``coarse`` equal segments and refined by bounded L-BFGS-B on
  the exact J and its analytic gradient, the best two again at ``fine`` segments; the
  lowest J kept.
* :func:`limited_yardstick` (the limits as :mod:`bench.toolkit.flight_limits` defines
  them): the in-box yardstick's candidates, its optimum and the straight line, each
  resampled to ``n_segments`` equal segments, then SLSQP on J with the limits, the box and
  near-equal segment lengths as constraints (a quadratic-penalty continuation with
  L-BFGS-B first when SLSQP ends infeasible); the lowest J among paths that pass the
  independent :func:`bench.toolkit.flight_limits.check_limits` kept.

Neither calls ``threat_planner.core.optimise``: the yardsticks are meant as a check on the
planner, so they share only the cost function with it.
"""

from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.sparse import coo_matrix

from bench.toolkit.flight_limits import check_limits, flight_limits, LimitConstraints, Limits
from bench.toolkit.grid import build_grid, edge_weights, GridGraph, least_route, route_points
from threat_planner.core.cost.closed_form import cost_and_gradient, path_cost
from threat_planner.core.world.threats import Box, ThreatField


def resample(points: NDArray, n_segments: int) -> NDArray:
    """Resample a polyline to ``n_segments`` segments of equal arc length (ends kept)."""
    p = np.asarray(points, float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n_segments + 1)
    out = np.stack([np.interp(t, s, p[:, k]) for k in range(3)], axis=1)
    out[0], out[-1] = p[0], p[-1]
    return out


def grid_routes(graph: GridGraph, w: float, routes: int = 4, penalty: float = 3.0
                ) -> list[NDArray]:
    """Dijkstra routes on the grid, each next one with earlier routes' edges penalised.

    Parameters
    ----------
    graph : GridGraph
        The grid with exact edge costs.
    w : float
        Threat weight.
    routes : int
        Number of routes.
    penalty : float
        Factor on the J of every edge an earlier route used.

    Returns
    -------
    list of ndarray, shape (k, 3)
        The routes, start to goal [m] (duplicates of an earlier route dropped).
    """
    weight, ok = edge_weights(graph, w)
    m = len(graph.nodes)
    a, b = graph.edge_a[ok], graph.edge_b[ok]
    idx = np.flatnonzero(ok)
    # Edge index + 1 by its two ends, so that a route's edges can be found from its nodes.
    lookup = coo_matrix((np.concatenate([idx, idx]) + 1.0,
                         (np.concatenate([a, b]), np.concatenate([b, a]))),
                        shape=(m, m)).tocsr()
    factor = np.ones(len(weight))
    out, seen = [], set()
    for _ in range(routes):
        route = least_route(graph, weight * factor, ok)
        if route is None:
            break
        seq = route[0]
        edges = np.asarray(lookup[seq[:-1], seq[1:]]).ravel().astype(int) - 1
        factor[edges] = penalty
        if tuple(seq) in seen:
            continue
        seen.add(tuple(seq))
        out.append(route_points(graph, seq))
    return out


def refine_in_box(points: NDArray, threats: ThreatField, w: float, box: Box,
                  maxiter: int = 3000) -> NDArray:
    """Minimise the exact J over the interior vertices by L-BFGS-B inside the box.

    Parameters
    ----------
    points : ndarray, shape (n+1, 3)
        Start path; its interior vertices are clipped into the box first [m].
    threats : ThreatField
        The threats.
    w : float
        Threat weight.
    box : Box
        Bounds of every interior vertex.
    maxiter : int
        L-BFGS-B iteration cap.

    Returns
    -------
    ndarray, shape (n+1, 3)
        The refined path (never of higher J than the clipped start).
    """
    p0 = np.asarray(points, float).copy()
    p0[1:-1] = box.clip(p0[1:-1])
    pos, f = threats.positions, threats.intensities

    def fun(z: NDArray) -> tuple[float, NDArray]:
        p = np.vstack([p0[:1], z.reshape(-1, 3), p0[-1:]])
        j, g = cost_and_gradient(p, pos, f, w)
        if not np.isfinite(j):
            return 1e300, np.zeros_like(z)
        return j, g[1:-1].ravel()

    bounds = list(zip(np.tile(box.lo, len(p0) - 2), np.tile(box.hi, len(p0) - 2)))
    res = minimize(fun, p0[1:-1].ravel(), jac=True, method='L-BFGS-B', bounds=bounds,
                   options={'maxiter': maxiter, 'maxfun': 3 * maxiter, 'ftol': 1e-13,
                            'gtol': 1e-9})
    out = np.vstack([p0[:1], res.x.reshape(-1, 3), p0[-1:]])
    j0 = path_cost(p0, pos, f, w).J
    return out if path_cost(out, pos, f, w).J <= j0 else p0


def in_box_yardstick(threats: ThreatField, start: NDArray, goal: NDArray, box: Box,
                     w: float, grid: int = 41, routes: int = 4, penalty: float = 3.0,
                     coarse: int = 20, fine: int = 60,
                     graph: GridGraph | None = None) -> dict:
    """Least J found inside the box without flight limits (see the module docstring).

    Parameters
    ----------
    threats, start, goal, box, w
        The problem: threats, end points [m], flight box and threat weight.
    grid : int
        Grid nodes per axis (ignored when ``graph`` is given).
    routes, penalty : int, float
        Alternative grid routes and the factor on earlier routes' edges.
    coarse, fine : int
        Segments of the first refinement (every seed) and the second (best two).
    graph : GridGraph, optional
        A prebuilt grid for these threats, start, goal and box (shared between w values).

    Returns
    -------
    dict
        ``J`` (exact ``path_cost`` of ``path``), ``path`` ((fine+1, 3) or (coarse+1, 3)
        [m]), ``seconds`` (grid build included), ``how`` (which seed won), ``grid``,
        ``n_segments`` and ``candidates``: every refined path with its ``how`` and ``J``.
    """
    t0 = time.perf_counter()
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    prebuilt = graph is not None
    if graph is None:
        graph = build_grid(threats, start, goal, box, n=grid)
    pos, f = threats.positions, threats.intensities
    seeds = [(f'grid route {k}', r) for k, r in enumerate(grid_routes(graph, w, routes,
                                                                      penalty))]
    seeds.append(('straight', np.array([start, goal])))
    cands = []
    for how, pts in seeds:
        p = refine_in_box(resample(pts, coarse), threats, w, box)
        cands.append({'how': how, 'n_segments': coarse, 'J': path_cost(p, pos, f, w).J,
                      'J_seed': path_cost(pts, pos, f, w).J, 'path': p})
    for c in sorted(cands, key=lambda c: c['J'])[:2]:
        p = refine_in_box(resample(c['path'], fine), threats, w, box)
        cands.append({'how': c['how'], 'n_segments': fine, 'J': path_cost(p, pos, f, w).J,
                      'J_seed': c['J'], 'path': p})
    best = min(cands, key=lambda c: c['J'])
    # A prebuilt graph was paid for once per scenario; count it in each of its cases.
    seconds = time.perf_counter() - t0 + (graph.build_s if prebuilt else 0.0)
    return {'J': best['J'], 'path': best['path'], 'how': best['how'],
            'n_segments': best['n_segments'], 'grid': int(round(len(graph.nodes) ** (1 / 3))),
            'seconds': seconds, 'grid_build_s': graph.build_s, 'candidates': cands}


def _slsqp(z0: NDArray, fun, cons: LimitConstraints, bounds, maxiter: int) -> NDArray:
    res = minimize(fun, z0, jac=True, method='SLSQP', bounds=bounds,
                   constraints=[{'type': 'ineq', 'fun': cons, 'jac': cons.jacobian}],
                   options={'maxiter': maxiter, 'ftol': 1e-12})
    return res.x


def _penalty_path(z0: NDArray, fun, cons: LimitConstraints, bounds) -> NDArray:
    """Quadratic-penalty continuation by L-BFGS-B towards the feasible set."""
    z = z0
    for mu in (1e1, 1e2, 1e3, 1e4, 1e5):
        def pen(x: NDArray, mu: float = mu) -> tuple[float, NDArray]:
            j, g = fun(x)
            c = np.minimum(cons(x), 0.0)
            return j + mu * float(c @ c), g + 2.0 * mu * (cons.jacobian(x).T @ c)
        z = minimize(pen, z, jac=True, method='L-BFGS-B', bounds=bounds,
                     options={'maxiter': 2000}).x
    return z


def limited_yardstick(threats: ThreatField, start: NDArray, goal: NDArray, box: Box,
                      w: float, max_climb_deg: float, max_dive_deg: float,
                      min_turn_radius_m: float, n_segments: int = 60, spacing: float = 1.5,
                      in_box: dict | None = None, grid: int = 41,
                      maxiter: int = 500, max_starts: int | None = None,
                      extra_starts: Sequence[tuple[str, NDArray]] = ()) -> dict:
    """Least J found inside the box that also respects the flight limits.

    Parameters
    ----------
    threats, start, goal, box, w
        The problem, as :func:`in_box_yardstick` takes it.
    max_climb_deg, max_dive_deg : float
        Largest climb and dive angle of a segment [deg].
    min_turn_radius_m : float
        Smallest circumradius at an interior vertex [m].
    n_segments : int
        Segments of the limited path (fixed: the turn-radius rule depends on it).
    spacing : float
        Every segment stays within [L0 / spacing, L0 * spacing], L0 the start path's
        length over n_segments.
    in_box : dict, optional
        The :func:`in_box_yardstick` result for this case (computed with ``grid`` if not
        given); its candidates are the starts.
    grid : int
        Grid nodes per axis when in_box is computed here.
    maxiter : int
        SLSQP iteration cap per run.
    max_starts : int, optional
        Use only the best this many in-box seeds (by refined J) besides the straight line;
        all of them if None.
    extra_starts : sequence of (str, ndarray), optional
        More starts, ``(how, path)``, tried after those (a planner's limit-free plan of the
        same case is a cheap good one); none by default.

    Returns
    -------
    dict
        ``J``, ``path``, ``seconds`` (this stage only), ``how`` (the winning start),
        ``n_segments``, ``limits``, ``achieved`` (``flight_limits`` of the path),
        ``feasible`` and ``starts`` (per start: ``how``, ``J``, ``feasible``).
    """
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    if in_box is None:
        in_box = in_box_yardstick(threats, start, goal, box, w, grid=grid)
    t0 = time.perf_counter()
    limits = Limits(float(max_climb_deg), float(max_dive_deg), float(min_turn_radius_m))
    pos, f = threats.positions, threats.intensities
    best_per_seed: dict[str, dict] = {}
    for c in in_box['candidates']:
        if c['how'] not in best_per_seed or c['J'] < best_per_seed[c['how']]['J']:
            best_per_seed[c['how']] = c
    ranked = sorted(best_per_seed.items(), key=lambda kv: kv[1]['J'])
    starts = [(how, c['path']) for how, c in ranked[:max_starts]]
    starts.append(('straight line', np.array([start, goal])))
    starts += [(how, np.asarray(path, float)) for how, path in extra_starts]
    bounds = list(zip(np.tile(box.lo, n_segments - 1), np.tile(box.hi, n_segments - 1)))
    best, report = None, []
    for how, path in starts:
        p0 = resample(path, n_segments)
        p0[1:-1] = box.clip(p0[1:-1])
        j0 = path_cost(p0, pos, f, w).J
        seg_ref = float(np.linalg.norm(np.diff(p0, axis=0), axis=1).sum()) / n_segments
        cons = LimitConstraints(start, goal, limits, seg_ref, spacing)

        def fun(z: NDArray, j0: float = j0) -> tuple[float, NDArray]:
            p = np.vstack([start, z.reshape(-1, 3), goal])
            j, g = cost_and_gradient(p, pos, f, w)
            if not np.isfinite(j):
                return 1e300, np.zeros_like(z)
            return j / j0, g[1:-1].ravel() / j0

        z = _slsqp(p0[1:-1].ravel(), fun, cons, bounds, maxiter)
        p = np.vstack([start, z.reshape(-1, 3), goal])
        ok = check_limits(p, limits) and box.contains(p)
        if not ok:
            z = _slsqp(_penalty_path(z, fun, cons, bounds), fun, cons, bounds, maxiter)
            p = np.vstack([start, z.reshape(-1, 3), goal])
            ok = check_limits(p, limits) and box.contains(p)
        j = path_cost(p, pos, f, w).J
        ok = ok and math.isfinite(j)  # a path through a threat is no yardstick
        report.append({'how': how, 'J': j, 'feasible': bool(ok)})
        if ok and (best is None or j < best['J']):
            best = {'J': j, 'path': p, 'how': how}
    if best is None:
        best = {'J': math.inf, 'path': np.array([start, goal]), 'how': 'none feasible'}
    return {'J': best['J'], 'path': best['path'], 'how': best['how'],
            'n_segments': n_segments, 'spacing': spacing, 'limits': limits.as_dict(),
            'achieved': flight_limits(best['path']), 'feasible': math.isfinite(best['J']),
            'seconds': time.perf_counter() - t0, 'starts': report}
