"""Planning inside an airspace: blocked edges, constrained optimisation, checked result.

The method is 'best' with three changes. (1) The routing graph is the incentre network
joined to a coarse lattice over the box (a large zone or a ridge can cut every long
Delaunay edge, and the lattice keeps a way around), and every edge or start/goal leg that
enters a zone or dips below terrain + clearance is removed (exact segment checks, see
``Airspace.segment_ok``). (2) Each seed path (the routes, which respect every constraint,
and the straight line) is minimised by SLSQP with the zones and the terrain floor as
constraints at sample points of every segment; since signed distances are 1-Lipschitz,
a sample keeps L/(2q) more than the limit (times the terrain's slope factor for the floor),
which keeps every point between samples clear. (3) Every result is checked exactly; only
paths that pass are kept, and the route itself is the fallback, so no path that enters a
zone is ever returned. With masking, edge weights and the optimiser use masked J_R (see
``core/cost/masking.py``) and the reported J is masked.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from threat_planner.core import _scipy_first  # noqa: F401,I100 (before any scipy)
from scipy.optimize import minimize
from scipy.spatial import cKDTree

from threat_planner.core.cost.closed_form import (cost_and_gradient, segment_integrals,
                                                  segment_threat_costs)
from threat_planner.core.cost.masking import (masked_cost, masked_cost_and_gradient,
                                              masked_segment_costs, visible_pieces)
from threat_planner.core.methods.problem import Candidate, Problem
from threat_planner.core.network.partition import Network
from threat_planner.core.network.search import alternative_routes, EdgeCosts
from threat_planner.core.optimise.limits import (constraint_jacobian, constraint_values,
                                                 FlightLimits)
from threat_planner.core.optimise.optimisation import aim
from threat_planner.core.optimise.smoothing import check_angles, resample
from threat_planner.core.world.airspace import Airspace
from threat_planner.errors import PlanningError

#: Lattice points along the box's longest side (others in proportion, at least 3).
LATTICE_DIVISIONS = 8
#: Lattice neighbours each network node is joined to.
LATTICE_LINKS = 4
#: Constraint samples per segment in the optimiser.
SAMPLES_PER_SEGMENT = 6
#: Extra margin kept from zones and the floor while optimising, fraction of the diagonal.
SAFETY_FRACTION = 1e-4
#: Segments of the coarse screening optimisation and of the SLSQP iteration limit.
COARSE_SEGMENTS = 8
SLSQP_ITERATIONS = 150
#: Samples per edge for the masked edge weights (a guide for the search only).
EDGE_MASK_SAMPLES = 5
#: Rounds of re-found seen pieces in a masked optimisation.
MASK_ROUNDS = 3


def lattice(box, divisions: int = LATTICE_DIVISIONS) -> tuple[NDArray, NDArray]:
    """Grid points over the box and their 26-neighbour edges."""
    size = box.hi - box.lo
    n = np.maximum(3, np.round(divisions * size / size.max()).astype(int) + 1)
    axes = [np.linspace(box.lo[k], box.hi[k], n[k]) for k in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing='ij'), -1).reshape(-1, 3)
    idx = np.arange(len(pts)).reshape(n)
    edges = []
    for dx in (0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if (dx, dy, dz) <= (0, 0, 0):
                    continue
                sl = [slice(0, n[0] - dx), slice(max(0, -dy), n[1] - max(0, dy)),
                      slice(max(0, -dz), n[2] - max(0, dz))]
                sh = [slice(dx, n[0]), slice(max(0, dy), n[1] - max(0, -dy)),
                      slice(max(0, dz), n[2] - max(0, -dz))]
                edges.append(np.stack([idx[tuple(sl)].ravel(), idx[tuple(sh)].ravel()], 1))
    return pts, np.concatenate(edges)


def routing_network(network: Network, box, airspace: Airspace, confine: bool = True
                    ) -> Network:
    """Join the network to a lattice and remove every edge that breaks the airspace.

    With ``confine``, edges to network nodes in the box's margin go too (the lattice
    covers the box), so that no route leaves the box.
    """
    pts, ledges = lattice(box)
    m = network.n_nodes
    _, near = cKDTree(pts).query(network.nodes, k=LATTICE_LINKS)
    links = np.stack([np.repeat(np.arange(m), LATTICE_LINKS), m + near.ravel()], 1)
    nodes = np.vstack([network.nodes, pts])
    edges = np.concatenate([network.edges, ledges + m, links])
    edges = np.sort(edges, axis=1)
    ok = np.ones(len(edges), bool)
    if confine:
        inside = np.all((nodes >= box.lo - 1e-9) & (nodes <= box.hi + 1e-9), axis=1)
        ok = inside[edges[:, 0]] & inside[edges[:, 1]]
    ok[ok] = airspace.segment_ok(nodes[edges[ok, 0]], nodes[edges[ok, 1]])
    return replace(network, nodes=nodes, edges=edges[ok])


def edge_costs(net: Network, threats, airspace: Airspace) -> EdgeCosts:
    """J_R of every edge, masked when the terrain masks (then from a few samples)."""
    a, b = net.nodes[net.edges[:, 0]], net.nodes[net.edges[:, 1]]
    if not airspace.masking or len(threats) == 0:
        c = segment_threat_costs(a, b, threats.positions, threats.intensities)
        return EdgeCosts(c, np.zeros(len(c)), None)
    # A guide for the search only (the reported J is exact): each radar's cost of an edge
    # scaled by the share of its ends and midpoint (weights 1/4, 1/2, 1/4) it sees;
    # visibility of a node is shared by all its edges.
    ter, pos = airspace.terrain, threats.positions
    n_t = len(pos)
    node_vis = np.stack([ter.visible(pos[i], net.nodes) for i in range(n_t)], 1)
    mid = 0.5 * (a + b)
    mid_vis = np.stack([ter.visible(pos[i], mid) for i in range(n_t)], 1)
    share = (0.25 * node_vis[net.edges[:, 0]] + 0.5 * mid_vis
             + 0.25 * node_vis[net.edges[:, 1]])
    per = segment_integrals(a, b, pos) * threats.intensities
    c = (per * share).sum(axis=1)
    return EdgeCosts(c, np.zeros(len(c)), None)


def segment_j_r(a: NDArray, b: NDArray, threats, airspace: Airspace) -> NDArray:
    """Exact (masked where the terrain masks) J_R of each segment."""
    if airspace.masking:
        return masked_segment_costs(a, b, threats.positions, threats.intensities,
                                    airspace.terrain)
    return segment_threat_costs(a, b, threats.positions, threats.intensities)


def _blocker(airspace: Airspace, a: NDArray, b: NDArray) -> str:
    """Label of the zone (or 'terrain') that most blocks the segment a->b."""
    v = airspace.violations(np.vstack([a, b]))
    return v[0][0] if v else 'the airspace'


def _constraints(airspace: Airspace, ends: tuple[NDArray, NDArray], q: int, safety: float,
                 limits: FlightLimits | None) -> list[dict]:
    """SLSQP inequality constraints g(z) >= 0 for zones, terrain floor and flight limits."""
    frac = (np.arange(q) + 0.5) / q
    lip = 1.0 if airspace.terrain is None else float(np.hypot(1.0,
                                                              airspace.terrain.max_slope))

    def unpack(z: NDArray) -> NDArray:
        return np.vstack([ends[0], z.reshape(-1, 3), ends[1]])

    def samples(p: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        a, b = p[:-1], p[1:]
        d = b - a
        length = np.linalg.norm(d, axis=1)
        u = d / np.where(length > 0, length, 1.0)[:, None]
        pts = a[:, None] + frac[None, :, None] * d[:, None]
        return pts, length, u, d

    def chain(grad_pts: NDArray, u: NDArray, slack: float, n_v: int) -> NDArray:
        # grad_pts (S, q, 3): d g / d sample; samples move with both ends; the L/(2q)
        # term moves with the ends through L.
        s = len(u)
        jac = np.zeros((s, q, n_v, 3))
        rows = np.arange(s)
        jac[rows, :, rows] += (1 - frac)[None, :, None] * grad_pts
        jac[rows, :, rows + 1] += frac[None, :, None] * grad_pts
        jac[rows, :, rows] += slack * u[:, None, :]
        jac[rows, :, rows + 1] -= slack * u[:, None, :]
        return jac.reshape(s * q, n_v, 3)[:, 1:-1].reshape(s * q, -1)

    out = []
    for zone in airspace.zones:
        def g(z, zone=zone):
            pts, length, _, _ = samples(unpack(z))
            return (zone.sdf(pts) - length[:, None] / (2 * q) - safety).ravel()

        def jac(z, zone=zone):
            p = unpack(z)
            pts, _, u, _ = samples(p)
            return chain(zone.sdf_grad(pts), u, 1.0 / (2 * q), len(p))
        out.append({'type': 'ineq', 'fun': g, 'jac': jac})
    if airspace.terrain is not None:
        ter = airspace.terrain

        def g_t(z):
            pts, length, _, _ = samples(unpack(z))
            above = pts[..., 2] - ter.height(pts[..., :2]) - ter.clearance
            return (above - lip * length[:, None] / (2 * q) - safety).ravel()

        def jac_t(z):
            p = unpack(z)
            pts, _, u, _ = samples(p)
            grad = np.concatenate([-ter.height_gradient(pts[..., :2]),
                                   np.ones(pts.shape[:-1] + (1,))], -1)
            return chain(grad, u, lip / (2 * q), len(p))
        out.append({'type': 'ineq', 'fun': g_t, 'jac': jac_t})
    if limits is not None and limits.any_constraint:
        def jac_l(z):
            jac = constraint_jacobian(unpack(z), limits)[:, 1:-1]
            return jac.reshape(len(jac), -1)
        out.append({'type': 'ineq', 'fun': lambda z: constraint_values(unpack(z), limits),
                    'jac': jac_l})
    return out


def minimise_in_airspace(points: NDArray, threats, w: float, box, airspace: Airspace,
                         limits: FlightLimits | None = None,
                         iterations: int = SLSQP_ITERATIONS) -> NDArray:
    """SLSQP on J (masked if the terrain masks) with the airspace as constraints.

    Args:
        points: Start path (n+1, 3) [m]; the ends stay fixed.
        threats: The threat field.
        w: Threat weight.
        box: Flight box (bounds), or None.
        airspace: Zones and terrain.
        limits: Physical flight limits to hold as constraints, or None.
        iterations: SLSQP iteration limit.

    Returns:
        The optimised path (not yet checked exactly: see ``Airspace.violations``).
    """
    x = np.asarray(points, float)
    if len(x) < 3:
        return x
    ends = (x[0].copy(), x[-1].copy())
    diag = float(np.linalg.norm(box.hi - box.lo)) if box is not None else 1.0
    safety = SAFETY_FRACTION * diag
    j_l0 = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum()) or 1.0
    spring = 1e-3 * (1.0 - w) * (len(x) - 1) / j_l0
    scale = {}
    state = {'pieces': None}

    def objective(z: NDArray) -> tuple[float, NDArray]:
        p = np.vstack([ends[0], z.reshape(-1, 3), ends[1]])
        if state['pieces'] is not None:
            j, g = masked_cost_and_gradient(p, threats.positions, threats.intensities, w,
                                            state['pieces'])
        else:
            j, g = cost_and_gradient(p, threats.positions, threats.intensities, w)
        d = np.diff(p, axis=0)
        j += spring * float(np.sum(d * d))
        g[:-1] -= 2.0 * spring * d
        g[1:] += 2.0 * spring * d
        if not np.isfinite(j):
            return 1e300, np.zeros_like(z)
        s = scale.setdefault('s', max(abs(j), 1e-12))
        return j / s, g[1:-1].ravel() / s

    bounds = (None if box is None else
              [(lo, hi) for _ in range(len(x) - 2) for lo, hi in zip(box.lo, box.hi)])
    cons = _constraints(airspace, ends, SAMPLES_PER_SEGMENT, safety, limits)
    if not airspace.masking:
        res = minimize(objective, x[1:-1].ravel(), jac=True, method='SLSQP', bounds=bounds,
                       constraints=cons, options={'maxiter': iterations, 'ftol': 1e-7})
        return np.vstack([ends[0], res.x.reshape(-1, 3), ends[1]])
    # Masked: the seen pieces are frozen for a round (a smooth, exact-gradient model),
    # then found again where the path went; the best exact masked J over rounds wins.
    best, best_j = x, masked_cost(x, threats, w, airspace).J
    for _ in range(MASK_ROUNDS):
        state['pieces'] = visible_pieces(x, threats.positions, airspace.terrain)
        res = minimize(objective, x[1:-1].ravel(), jac=True, method='SLSQP', bounds=bounds,
                       constraints=cons, options={'maxiter': iterations, 'ftol': 1e-7})
        x = np.vstack([ends[0], res.x.reshape(-1, 3), ends[1]])
        j = masked_cost(x, threats, w, airspace).J
        if not airspace.violations(x) and j < best_j:
            best, best_j = x, j
        elif j >= best_j:
            break
    return best


def plan_in_airspace(p: Problem) -> Candidate:
    """Solve Problem ``p`` with method 'best' inside its airspace (see the module docstring)."""
    cfg, threats, air = p.config, p.threats, p.airspace
    box = p.box if cfg.confine_to_box else None
    net = routing_network(p.network, p.box, air, cfg.confine_to_box)
    p.network = net
    p.clock.lap('partition_ms')
    ej = edge_costs(net, threats, air)
    p.edge_j = ej
    p.clock.lap('edge_costs_ms')
    legs = {}
    for name, point in (('start', p.s), ('goal', p.t)):
        k = min(net.n_nodes, max(cfg.entry_candidates, 8) * 4)
        cand = net.nearest(point, k)
        ends = np.repeat(point[None], len(cand), 0)
        ok = air.segment_ok(ends, net.nodes[cand])
        if not ok.any():
            raise PlanningError(f'{name}: every way out of {point.tolist()} is blocked by '
                                f'{_blocker(air, point, net.nodes[cand[0]])}')
        cand = cand[ok][:cfg.entry_candidates]
        a, b = (ends[:len(cand)], net.nodes[cand]) if name == 'start' else \
            (net.nodes[cand], ends[:len(cand)])
        lengths = np.linalg.norm(b - a, axis=1)
        legs[name] = (cand, ej.combine(segment_j_r(a, b, threats, air), lengths, cfg.w))
    try:
        routes = alternative_routes(net, ej.weights(net.edge_lengths, cfg.w),
                                    legs['start'][1], legs['start'][0], legs['goal'][1],
                                    legs['goal'][0], cfg.routes)
    except PlanningError:
        raise PlanningError(f'airspace: no route from start to goal avoids '
                            f'{_blocker(air, p.s, p.t)}') from None
    p.clock.lap('search_ms')
    seeds = [(f'route {i}', seq, np.vstack([p.s, net.nodes[seq], p.t]))
             for i, seq in enumerate(routes)]
    seeds.append(('straight line', routes[0], np.vstack([p.s, p.t])))
    screened = []
    for name, seq, initial in seeds:
        route_ok = name != 'straight line'
        coarse = minimise_in_airspace(resample(initial, COARSE_SEGMENTS), threats, cfg.w,
                                      box, air)
        if air.violations(coarse):
            if not route_ok:
                continue
            coarse = resample(initial, COARSE_SEGMENTS)
        screened.append((p.cost(coarse).J, name, seq, coarse))
    screened.sort(key=lambda item: item[0])
    p.clock.lap('screening_ms')
    best = None
    for _, name, seq, coarse in screened[:3]:
        start = resample(coarse, cfg.n_points)
        # SLSQP ends on the constraints it is given, so the exact check would pass or fail as
        # the last bit falls (air_geofence_0 at w 0.5 missed the 10 m turn radius by 2.1 mm,
        # air_ridges_mask_0 at w 0.8 by 2.0 mm on OpenBLAS's Haswell kernels only).
        opt = minimise_in_airspace(start, threats, cfg.w, box, air, aim(p.limits))
        if air.violations(opt) or (box is not None and not _in_box(opt, box)):
            opt = start      # the resampled screened path respects every constraint
        cand = Candidate(seq=seq, initial=np.vstack([p.s, net.nodes[seq], p.t]),
                         smoothed=None, smoothed_cost=None, final=opt, k=float('nan'),
                         steps=0, converged=True, cost=p.cost(opt),
                         angles=check_angles(opt, cfg.max_pitch_deg, cfg.max_turn_deg),
                         seed=name, limit_check=p.check(opt))
        if best is None or ((cand.limit_check.feasible, -cand.cost.J)
                            > (best.limit_check.feasible, -best.cost.J)):
            best = cand
        if best.limit_check.feasible:
            break
    p.clock.lap('optimisation_ms')
    return best


def _in_box(points: NDArray, box, tol: float = 1e-9) -> bool:
    return bool(np.all(points >= box.lo - tol) and np.all(points <= box.hi + tol))
