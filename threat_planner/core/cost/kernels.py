"""Compiled kernels (numba) for J and its gradient on the optimiser's hot path.

The closed form of :mod:`.closed_form`, pair by pair (:mod:`.pair_integrals`),
written as one loop over (segment, threat) pairs so that a 40-segment, 20-threat
evaluation costs microseconds instead of the ~0.3 ms numpy spends on call overhead.
``cache=True`` keeps the compiled code on disk (in a folder named by a hash of the
kernels' sources, :mod:`._numba_cache`): the first call in a fresh environment compiles
(about 2 s, measured in ``bench/results/speed.md``), later processes load it in
milliseconds. Without numba the same functions run as plain Python (correct, slow); numba
is an install requirement.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
import math
import threading

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.closed_form import _C2, _C3, Cost
from threat_planner.core.cost.pair_integrals import (_direct, _DIRECT_REACH, _far, _foot,
                                                     _pair_integral, _segment_total, HAVE_NUMBA,
                                                     njit, prange)

__all__ = ['HAVE_NUMBA', 'cost_gradient', 'path_cost', 'segment_costs', 'warm_up']


@njit(cache=True)
def _kernel(points, positions, f, w, seg, thr, c2, c3, grad):
    """J and its gradient (into grad) over the given pairs; seg[0] < 0 means all pairs."""
    n_seg = points.shape[0] - 1
    n_thr = positions.shape[0]
    dense = seg.shape[0] == 0
    n_pairs = n_seg * n_thr if dense else seg.shape[0]
    grad[:, :] = 0.0
    # Each segment's unit vector, length and its inverse, once (not once per threat).
    sd = np.empty((n_seg, 5))
    j_l = 0.0
    for s in range(n_seg):
        dx = points[s + 1, 0] - points[s, 0]
        dy = points[s + 1, 1] - points[s, 1]
        dz = points[s + 1, 2] - points[s, 2]
        ln = math.sqrt(dx * dx + dy * dy + dz * dz)
        j_l += ln
        sd[s, 3] = ln
        if ln > 0:
            il = 1.0 / ln
            sd[s, 0], sd[s, 1], sd[s, 2], sd[s, 4] = dx * il, dy * il, dz * il, il
            g = (1.0 - w) * il
            grad[s, 0] -= g * dx
            grad[s, 1] -= g * dy
            grad[s, 2] -= g * dz
            grad[s + 1, 0] += g * dx
            grad[s + 1, 1] += g * dy
            grad[s + 1, 2] += g * dz
    j_r = 0.0
    # Runs of pairs on one segment (a segment's threats when dense): the gradients of its
    # two ends are summed in registers and stored once per run, not six times per pair
    # (each end's additions in the same order as pair by pair: the same bits). Dense, 40
    # segments x 20 threats: 9-15 % faster over two runs; a cut-off's pairs (sorted by
    # segment) within 2 % of before (bench/results/profile_kernel.txt).
    k = 0
    while k < n_pairs:
        s = k // n_thr if dense else seg[k]
        end = k + n_thr
        if not dense:
            end = k + 1
            while end < n_pairs and seg[end] == s:
                end += 1
        ln = sd[s, 3]
        if ln == 0:
            k = end
            continue
        ux, uy, uz, il = sd[s, 0], sd[s, 1], sd[s, 2], sd[s, 4]
        x0, y0, z0 = points[s, 0], points[s, 1], points[s, 2]
        gax, gay, gaz = grad[s, 0], grad[s, 1], grad[s, 2]
        gbx, gby, gbz = grad[s + 1, 0], grad[s + 1, 1], grad[s + 1, 2]
        for q in range(k, end):
            i = q - k if dense else thr[q]
            t1, t2, px, py, pz, h2, h, hit = _foot(x0, y0, z0, ux, uy, uz, ln, positions, i)
            if hit:
                return math.inf
            ida = 1.0 / (t1 * t1 + h2)
            idb = 1.0 / (t2 * t2 + h2)
            # The form chosen here, not in a shared helper: returning one helper's tuple
            # from either branch made this loop 20.5 -> 34.7 us (profile_kernel.py).
            reach = _DIRECT_REACH * h
            if abs(t1) <= reach and abs(t2) <= reach:
                i2, i3 = _direct(t1, t2, h, h2, ln, ida, idb)
            else:
                i2, i3 = _far(t1, t2, h, c2, c3)
            fi = f[i]
            j_r += fi * i2
            phi_a = fi * ida * ida
            phi_b = fi * idb * idb
            m0 = 4.0 * fi * i3
            coef_a = (phi_a - phi_b) * il - m0 * (1.0 + t1 * il)
            coef_b = (phi_b - phi_a) * il + m0 * t1 * il
            gax += w * (coef_a * px - phi_a * ux)
            gay += w * (coef_a * py - phi_a * uy)
            gaz += w * (coef_a * pz - phi_a * uz)
            gbx += w * (coef_b * px + phi_b * ux)
            gby += w * (coef_b * py + phi_b * uy)
            gbz += w * (coef_b * pz + phi_b * uz)
        grad[s, 0], grad[s, 1], grad[s, 2] = gax, gay, gaz
        grad[s + 1, 0], grad[s + 1, 1], grad[s + 1, 2] = gbx, gby, gbz
        k = end
    return w * j_r + (1.0 - w) * j_l


@njit(cache=True)
def _segment_costs(a, b, positions, f, seg, thr, c2, c3, out):
    """J_R of each segment into out, over the given pairs; seg empty means all pairs."""
    out[:] = 0.0
    if seg.shape[0] == 0:
        for s in range(a.shape[0]):
            out[s] = _segment_total(a, b, s, positions, f, c2, c3)
    else:
        for k in range(seg.shape[0]):
            out[seg[k]] += f[thr[k]] * _pair_integral(a, b, seg[k], positions, thr[k], c2, c3)


@njit(cache=True, parallel=True)
def _segment_costs_parallel(a, b, positions, f, c2, c3, out):
    """:func:`_segment_costs` over all pairs, the segments in parallel."""
    for s in prange(a.shape[0]):
        out[s] = _segment_total(a, b, s, positions, f, c2, c3)


#: Pairs per evaluation from which J and its gradient run on several threads (measured:
#: 8 segments x 1,000 threats 761 -> 456 us, 40 x 1,000 3.6 -> 2.0 ms on 2 cores).
PARALLEL_PAIRS = 4_000
#: Pairs from which segment_costs runs on several threads, a call at a time: a parallel
#: region woken between serial work paid for the wake-up on this shared host (a 20-threat
#: network's 6,000 edge pairs: serial 0.8 ms a plan, parallel 1.1-1.3 ms when the host was
#: quiet and 6-7.7 ms when it was busy).
SEGMENT_PARALLEL_PAIRS = 20_000
#: numba's default (workqueue) threading layer must not be entered by two threads at
#: once (the plan service and the node may plan concurrently in one process).
PARALLEL_LOCK = threading.Lock()


def parallel_guard(pairs: int) -> AbstractContextManager:
    """Return the lock to hold around a compiled call of this many pairs (none below)."""
    return PARALLEL_LOCK if pairs >= PARALLEL_PAIRS else nullcontext()


#: Segment chunks of a parallel evaluation.
_CHUNKS = 4


@njit(cache=True, parallel=True)
def _kernel_split(points, positions, f, w, seg, thr, c2, c3, grad):
    """:func:`_kernel` over chunks of segments in parallel; pairs sorted by segment."""
    n_seg = points.shape[0] - 1
    chunks = min(_CHUNKS, n_seg)
    dense = seg.shape[0] == 0
    sb = np.empty(chunks + 1, np.int64)
    for c in range(chunks + 1):
        sb[c] = (n_seg * c) // chunks
    pb = np.searchsorted(seg, sb) if not dense else sb
    bufs = np.zeros((chunks, n_seg + 1, 3))
    vals = np.zeros(chunks)
    for c in prange(chunks):
        lo = sb[c]
        hi = sb[c + 1]
        sub = points[lo:hi + 1]
        g = bufs[c, :hi - lo + 1]
        if dense:
            vals[c] = _kernel(sub, positions, f, w, seg, thr, c2, c3, g)
        elif pb[c + 1] > pb[c]:
            vals[c] = _kernel(sub, positions, f, w, seg[pb[c]:pb[c + 1]] - lo,
                              thr[pb[c]:pb[c + 1]], c2, c3, g)
        else:
            # No pair in this chunk: its length only (an empty pair list means all).
            vals[c] = _kernel(sub, positions[:0], f, w, seg[:0], thr[:0], c2, c3, g)
    grad[:, :] = 0.0
    total = 0.0
    for c in range(chunks):
        grad[sb[c]:sb[c + 1] + 1] += bufs[c, :sb[c + 1] - sb[c] + 1]
        total += vals[c]
    return total


_NO_PAIRS = np.zeros(0, np.int64)


def _frozen(a: NDArray) -> NDArray:
    """Return a read-only C-contiguous float view: numba compiles one signature for all callers."""
    v = np.ascontiguousarray(a, float).view()
    v.flags.writeable = False
    return v


def cost_gradient(points: NDArray, positions: NDArray, intensities: NDArray, w: float,
                  pairs: tuple[NDArray, NDArray] | None = None) -> tuple[float, NDArray]:
    """J of a polyline and its gradient, as :func:`cost.cost_and_gradient`, compiled.

    Parameters
    ----------
    points : ndarray
        Polyline vertices, (n, 3) [m].
    positions : ndarray
        Threat positions, (N, 3) [m].
    intensities : ndarray
        Threat intensities F, (N,).
    w : float
        Threat weight, 0 < w < 1.
    pairs : tuple of ndarray, optional
        ``(segment_index, threat_index)`` restricting the threat sum; all pairs if None.

    Returns
    -------
    tuple
        ``(J, grad)`` with grad (n, 3); J is inf (and grad zero) when a segment hits a
        threat.

    """
    points = np.ascontiguousarray(points, float)
    grad = np.zeros_like(points)
    if pairs is None:
        seg = thr = _NO_PAIRS
        if len(positions) == 0:
            positions = np.zeros((0, 3))
    else:
        seg = np.ascontiguousarray(pairs[0], np.int64)
        thr = np.ascontiguousarray(pairs[1], np.int64)
        if len(seg) == 0:
            # An empty pair list means no threat counted, not every pair.
            positions = np.zeros((0, 3))
            seg = thr = _NO_PAIRS
    j = _kernel(points, _frozen(positions), _frozen(intensities), float(w), seg, thr,
                _FROZEN_C2, _FROZEN_C3, grad)
    if not math.isfinite(j):
        grad[:] = 0.0
    return float(j), grad


_FROZEN_C2, _FROZEN_C3 = _frozen(_C2), _frozen(_C3)


def segment_costs(a: NDArray, b: NDArray, positions: NDArray, intensities: NDArray,
                  pairs: tuple[NDArray, NDArray] | None = None) -> NDArray:
    """J_R of each segment (eq. 17, our convention), as :mod:`.cost`'s, compiled.

    Parameters
    ----------
    a, b : ndarray
        Segment starts and ends, (S, 3) [m].
    positions : ndarray
        Threat positions, (N, 3) [m].
    intensities : ndarray
        Threat intensities F, (N,).
    pairs : tuple of ndarray, optional
        ``(segment_index, threat_index)`` restricting the sum; all pairs if None.

    Returns
    -------
    ndarray
        (S,) threat costs; inf where a segment hits a threat.

    """
    a = np.ascontiguousarray(a, float)
    out = np.zeros(len(a))
    if len(a) == 0 or len(positions) == 0:
        return out
    if pairs is None:
        seg = thr = _NO_PAIRS
    else:
        if len(pairs[0]) == 0:
            return out
        seg = np.ascontiguousarray(pairs[0], np.int64)
        thr = np.ascontiguousarray(pairs[1], np.int64)
    b = np.ascontiguousarray(b, float)
    if len(seg) == 0 and len(a) * len(positions) >= SEGMENT_PARALLEL_PAIRS:
        with PARALLEL_LOCK:
            _segment_costs_parallel(a, b, _frozen(positions), _frozen(intensities),
                                    _FROZEN_C2, _FROZEN_C3, out)
    else:
        _segment_costs(a, b, _frozen(positions), _frozen(intensities), seg, thr,
                       _FROZEN_C2, _FROZEN_C3, out)
    return out


@njit(cache=True)
def _path_threat_cost(points, positions, f, c2, c3):
    """J_R of a polyline over every threat, in one pass."""
    j_r = 0.0
    for s in range(points.shape[0] - 1):
        j_r += _segment_total(points[:-1], points[1:], s, positions, f, c2, c3)
    return j_r


def path_cost(points: NDArray, positions: NDArray, intensities: NDArray, w: float) -> Cost:
    """Cost of a polyline as :func:`.cost.path_cost` (the same closed form), compiled."""
    points = np.ascontiguousarray(points, float)
    # J_L as cost.path_cost sums it, to the last bit.
    j_l = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    # Through segment_costs only where it runs in parallel; serially, one pass here.
    if (len(points) - 1) * len(positions) >= SEGMENT_PARALLEL_PAIRS:
        j_r = float(segment_costs(points[:-1], points[1:], positions, intensities).sum())
    elif len(positions) == 0 or len(points) < 2:
        j_r = 0.0
    else:
        j_r = _path_threat_cost(points, _frozen(positions), _frozen(intensities), _FROZEN_C2,
                                _FROZEN_C3)
    return Cost(w * j_r + (1.0 - w) * j_l, j_l, j_r)


def warm_up() -> None:
    """Compile (or load from the cache) every kernel once, on a tiny problem."""
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.2], [2.0, 1.0, 0.0]])
    cost_gradient(pts, np.array([[1.0, 2.0, 0.0]]), np.array([1.0]), 0.5)
    cost_gradient(pts, np.array([[1.0, 2.0, 0.0]]), np.array([1.0]), 0.5,
                  (np.array([0, 1]), np.array([0, 0])))
    segment_costs(pts[:-1], pts[1:], np.array([[1.0, 2.0, 0.0]]), np.array([1.0]))
    segment_costs(pts[:-1], pts[1:], np.array([[1.0, 2.0, 0.0]]), np.array([1.0]),
                  (np.array([0, 1]), np.array([0, 0])))
    segment_costs(np.zeros((SEGMENT_PARALLEL_PAIRS, 3)), np.ones((SEGMENT_PARALLEL_PAIRS, 3)),
                  np.array([[1.0, 2.0, 0.0]]), np.array([1.0]))
