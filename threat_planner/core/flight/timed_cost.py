"""Exact J of a path flown in time through threats that move, appear and leave.

Convention (docs/method.md, "Threats in time"): J_L is the polyline's length; J_R is the
sum over segments and threat pieces of ``F * integral ds / |p(s) - q(t(s))|^4`` over the
part of the segment flown while the piece is active, ``t(s)`` the planned (or flown) time
at arc length ``s``. With static threats present throughout it is the J of
:func:`threat_planner.core.cost.closed_form.path_cost`.

On a segment flown from ``a`` at ``ta`` to ``b`` at ``tb`` (speed ``V = L / (tb - ta)``)
and a piece moving at ``v``, the relative position ``p - q`` is linear in time,
``c + (tau - tau1) g`` with ``g = (b - a) / (tb - ta) - v``. So the integral is
``V / |g|`` times the static closed form along the straight relative segment from ``c``
to ``c + (tau2 - tau1) g`` with the threat at the origin: exact, no sampling.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from threat_planner.core.cost.closed_form import Cost, pair_integrals
from threat_planner.core.cost.kernels import segment_costs
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.errors import InputError

__all__ = ['closest_approach', 'timed_path_cost', 'timed_segment_costs']

#: Largest (segment, piece) pairs evaluated at once.
_CHUNK = 500_000


def _timed(points: ArrayLike, times: ArrayLike) -> tuple[NDArray, NDArray]:
    pts = np.asarray(points, float).reshape(-1, 3)
    t = np.asarray(times, float).reshape(-1)
    if len(t) != len(pts):
        raise InputError(f'times: {len(t)} times for {len(pts)} points')
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        raise InputError('times: must be finite and non-decreasing along the path')
    return pts, t


def _pairs(pts: NDArray, t: NDArray, pieces: tuple, seg: slice):
    """Overlapping (segment, piece) pairs of the segments in `seg` and their geometry."""
    ids, f, origin, vel, on, off, _ = pieces
    a, b = pts[:-1][seg], pts[1:][seg]
    ta, tb = t[:-1][seg], t[1:][seg]
    lo = np.maximum(ta[:, None], on[None])
    hi = np.minimum(tb[:, None], off[None])
    si, pi = np.nonzero(hi > lo)
    dt = (tb - ta)[si]
    step = (b - a)[si] / dt[:, None]
    t1, t2 = lo[si, pi], hi[si, pi]
    p1 = a[si] + step * (t1 - ta[si])[:, None]
    c = p1 - (origin[pi] + vel[pi] * (t1 - on[pi])[:, None])
    g = step - vel[pi]
    return si, pi, f[pi], c, g, t2 - t1, np.linalg.norm(step, axis=1)


def timed_segment_costs(points: ArrayLike, times: ArrayLike, timeline: ThreatTimeline
                        ) -> NDArray:
    """J_R of each segment of a timed path (module docstring).

    Parameters
    ----------
    points : array_like
        Path vertices (M, 3) [m].
    times : array_like
        Time at each vertex (M,) [s], non-decreasing.
    timeline : ThreatTimeline
        The threats in time.

    Returns
    -------
    NDArray
        (M - 1,) threat cost of each segment; inf where a threat is met.

    """
    pts, t = _timed(points, times)
    out = np.zeros(max(len(pts) - 1, 0))
    if len(out) == 0:
        return out
    pieces = timeline.pieces()
    _, f_all, origin, vel, on, off, _ = pieces
    # A piece that stands still over the whole flight costs what the static closed form
    # says: the compiled kernel takes those (a 1,000-threat path: 81 ms in numpy).
    still = (~np.any(vel != 0.0, axis=1)) & (on <= t[0]) & (off >= t[-1])
    if still.any():
        out += segment_costs(pts[:-1], pts[1:], origin[still], f_all[still])
    pieces = tuple(a[~still] for a in pieces)
    n_pieces = max(len(pieces[0]), 1)
    step = max(1, _CHUNK // n_pieces)
    for s0 in range(0, len(out), step):
        si, _, f, c, g, dur, speed = _pairs(pts, t, pieces, slice(s0, s0 + step))
        gn = np.linalg.norm(g, axis=1)
        # Where the threat keeps pace with the UAV the distance is constant.
        still = gn <= 1e-12 * np.maximum(speed, 1.0)
        with np.errstate(divide='ignore', invalid='ignore'):
            moving = pair_integrals(c, c + g * dur[:, None], np.zeros_like(c)) * (
                speed / np.where(still, 1.0, gn))
            const = speed * dur / np.sum(c * c, axis=1) ** 2
        val = f * np.where(still, const, moving)
        out[s0:s0 + step] += np.bincount(si, val, minlength=len(out[s0:s0 + step]))
    return out


def timed_path_cost(points: ArrayLike, times: ArrayLike, timeline: ThreatTimeline,
                    w: float) -> Cost:
    """Exact J = w J_R + (1 - w) J_L of a timed path (module docstring).

    Parameters
    ----------
    points, times : array_like
        Path vertices (M, 3) [m] and their times (M,) [s].
    timeline : ThreatTimeline
        The threats in time.
    w : float
        Threat weight, 0 < w < 1.

    Returns
    -------
    Cost
        J, J_L [m] and J_R.

    """
    pts, t = _timed(points, times)
    j_l = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    j_r = float(np.sum(timed_segment_costs(pts, t, timeline)))
    return Cost(w * j_r + (1.0 - w) * j_l, j_l, j_r)


def closest_approach(points: ArrayLike, times: ArrayLike, timeline: ThreatTimeline
                     ) -> tuple[NDArray, NDArray]:
    """Closest distance of each threat piece to the timed path, and when.

    Parameters
    ----------
    points, times : array_like
        Path vertices (M, 3) [m] and their times (M,) [s].
    timeline : ThreatTimeline
        The threats in time.

    Returns
    -------
    distance : NDArray
        (P,) smallest distance [m] while the piece is active; inf if it never is then.
    when : NDArray
        (P,) the time of it [s]; NaN where the distance is inf.

    """
    pts, t = _timed(points, times)
    n_pieces = len(timeline.pieces()[0])
    dist = np.full(n_pieces, np.inf)
    when = np.full(n_pieces, np.nan)
    if len(pts) < 2 or n_pieces == 0:
        return dist, when
    _, _, _, _, on, _, _ = timeline.pieces()
    step = max(1, _CHUNK // n_pieces)
    for s0 in range(0, len(pts) - 1, step):
        seg = slice(s0, s0 + step)
        si, pi, _, c, g, dur, _ = _pairs(pts, t, timeline.pieces(), seg)
        g2 = np.sum(g * g, axis=1)
        with np.errstate(divide='ignore', invalid='ignore'):
            tau = np.clip(np.where(g2 > 0, -np.sum(c * g, axis=1) / g2, 0.0), 0.0, dur)
        d = np.linalg.norm(c + g * tau[:, None], axis=1)
        t1 = np.maximum(t[:-1][seg][si], on[pi])
        order = np.lexsort((d, pi))   # per piece, its nearest pair first
        first = np.ones(len(order), bool)
        first[1:] = pi[order][1:] != pi[order][:-1]
        k = order[first]
        better = d[k] < dist[pi[k]]
        dist[pi[k][better]] = d[k][better]
        when[pi[k][better]] = (t1 + tau)[k][better]
    return dist, when
