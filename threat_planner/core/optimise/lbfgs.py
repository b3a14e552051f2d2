"""Compiled (numba) bound-constrained L-BFGS over the optimiser's whole objective.

One call runs a whole minimisation: J (:mod:`.kernels`), the spacing terms and the flight
limits' augmented Lagrangian term (:mod:`.limit_kernels`), fused into one objective, and a
projected L-BFGS on it. It replaced scipy's L-BFGS-B, whose Python callback cost ~0.5 ms
per evaluation against ~0.06 ms for the objective itself at 40 segments and 20 threats
(measured in ``bench/results/profile_limits_after.txt``), and ~0.35 ms against 0.015 ms on
the 8-segment screening runs.

The method (projected quasi-Newton, as in Kim, Sra and Dhillon 2010): variables at a bound
whose gradient points out of the box are held; the two-loop recursion runs on the others;
a backtracking line search along the projected arc, Armijo condition on the actual step;
curvature pairs with s.y <= 0 are skipped. The initial inverse Hessian is the inverse of
the path's second-difference matrix (the Hessian of a spring chain; a tridiagonal solve
per axis) rather than a multiple of the identity: the length and spacing terms couple
neighbours, which conditions the problem as n^2 (measured on the 21 bundled cases: 25 %
fewer segment-evaluations at the median, with limits on and off, J equal or lower; the
caller turns it off on crowded fields and under a cut-off, see :mod:`.optimisation`). It
stops, like L-BFGS-B, when an iteration lowers the objective by less than ``ftol`` of it
or the largest free gradient component is below ``gtol``. The path's ends are variables
with equal bounds, so they never move.
"""

from __future__ import annotations

import math

import numpy as np

from threat_planner.core.cost.kernels import (_kernel, _kernel_split, njit, parallel_guard,
                                              PARALLEL_PAIRS)
from threat_planner.core.optimise.limit_kernels import _penalty

__all__ = ['minimise', 'objective', 'objective_scale']

#: Armijo constant and the backtracking factor of the line search.
_ARMIJO = 1e-4
_BACKTRACK = 0.5
_MAX_BACKTRACKS = 40


@njit(cache=True)
def _sum_squares(v):
    """Sum of v's squares in index order (np.dot calls BLAS: core/_vector.py)."""
    total = 0.0
    for k in range(v.shape[0]):
        total += v[k] * v[k]
    return total


@njit(cache=True)
def _objective(x, n1, positions, f, w, seg, thr, c2, c3, spring, even, scale, lim, lam, mu,
               gbuf, pgrad, grad, parts):
    """Scaled J + spacing terms (+ the limits' PHR term if lim[6]); gradient into grad.

    ``parts`` (2,) receives the unscaled J + spring term and J + both spacing terms (what
    the caller compares between runs, without evaluating the path again).
    """
    p = x.reshape((n1, 3))
    g = grad.reshape((n1, 3))
    pairs = seg.shape[0] if seg.shape[0] else (n1 - 1) * positions.shape[0]
    if pairs >= PARALLEL_PAIRS:
        j = _kernel_split(p, positions, f, w, seg, thr, c2, c3, g)
    else:
        j = _kernel(p, positions, f, w, seg, thr, c2, c3, g)
    if not math.isfinite(j):
        grad[:] = 0.0
        parts[0] = parts[1] = 1e300
        return 1e300
    n = n1 - 1
    sum_l = 0.0
    sum_l2 = 0.0
    for s in range(n):
        dx = p[s + 1, 0] - p[s, 0]
        dy = p[s + 1, 1] - p[s, 1]
        dz = p[s + 1, 2] - p[s, 2]
        d2 = dx * dx + dy * dy + dz * dz
        j += spring * d2
        sum_l += math.sqrt(d2)
        sum_l2 += d2
        g[s, 0] -= 2.0 * spring * dx
        g[s, 1] -= 2.0 * spring * dy
        g[s, 2] -= 2.0 * spring * dz
        g[s + 1, 0] += 2.0 * spring * dx
        g[s + 1, 1] += 2.0 * spring * dy
        g[s + 1, 2] += 2.0 * spring * dz
    spring_j = j
    if even > 0.0 and n > 0:
        # n Var(segment length) = sum l^2 - (sum l)^2 / n: even spacing without the pull
        # towards a shorter path a plain spring has.
        mean = sum_l / n
        j += even * (sum_l2 - mean * mean * n)
        for s in range(n):
            dx = p[s + 1, 0] - p[s, 0]
            dy = p[s + 1, 1] - p[s, 1]
            dz = p[s + 1, 2] - p[s, 2]
            ln = math.sqrt(dx * dx + dy * dy + dz * dz)
            c = 2.0 * even * (1.0 - mean / ln) if ln > 0 else 0.0
            g[s, 0] -= c * dx
            g[s, 1] -= c * dy
            g[s, 2] -= c * dz
            g[s + 1, 0] += c * dx
            g[s + 1, 1] += c * dy
            g[s + 1, 2] += c * dz
    parts[0] = spring_j
    parts[1] = j
    val = j / scale
    for k in range(grad.shape[0]):
        grad[k] /= scale
    if lim[6] > 0.0:
        pen, _ = _penalty(p, lim[0], lim[1], lim[2], lim[3] > 0.0, lim[4] > 0.0,
                          lim[5] > 0.0, lam, mu, gbuf, pgrad)
        val += pen
        grad += pgrad.reshape(-1)
    return val


@njit(cache=True)
def objective_scale(value):
    """Scale of the objective from its value at the start: |value|, finite and positive."""
    return max(abs(value), 1e-12) if math.isfinite(value) and value < 1e299 else 1.0


@njit(cache=True)
def _tri_solve(v, free, n1, out, cp, dp):
    """Solve L out = v per axis, L the second-difference matrix of the free vertices.

    L (2 on the diagonal, -1 between neighbours) is the Hessian of the path's spring
    energy; held vertices and the ends are fixed (their rows decoupled, out zero there).
    """
    for k in range(3):
        prev = False
        for i in range(n1):
            j = 3 * i + k
            if free[j] == 0.0:
                cp[i] = dp[i] = 0.0
                prev = False
                continue
            c = -1.0 if i + 1 < n1 and free[j + 3] != 0.0 else 0.0
            den = 2.0 + cp[i - 1] if prev else 2.0
            cp[i] = c / den
            dp[i] = (v[j] + dp[i - 1]) / den if prev else v[j] / den
            prev = True
        nxt = 0.0
        for i in range(n1 - 1, -1, -1):
            j = 3 * i + k
            out[j] = 0.0 if free[j] == 0.0 else dp[i] - cp[i] * nxt
            nxt = out[j]


@njit(cache=True)
def _minimise(x0, lo, hi, positions, f, w, seg, thr, c2, c3, spring, even, scale, lim,
              lam, mu, gbuf, pgrad, maxiter, ftol, gtol, m, max_step, pre, reach, out,
              parts):
    """Projected L-BFGS from x0 within [lo, hi] (preconditioned if pre); minimiser into out.

    ``scale`` <= 0: :func:`objective_scale` of J + spacing terms at the start. ``parts``
    receives :func:`_objective`'s parts at the minimiser. Returns (value, iterations,
    evaluations, why it stopped: 0 small decrease, 1 small gradient, 2 no step accepted,
    3 iteration limit, 4 a vertex moved beyond reach).
    """
    nv = x0.shape[0]
    n1 = nv // 3
    x = np.minimum(np.maximum(x0, lo), hi)
    g = np.zeros(nv)
    trial = np.zeros(2)
    fx = _objective(x, n1, positions, f, w, seg, thr, c2, c3, spring, even,
                    1.0 if scale <= 0.0 else scale, lim, lam, mu, gbuf, pgrad, g, parts)
    if scale <= 0.0:
        # (j / 1) / s is j / s exactly: the same start as a call given s.
        scale = objective_scale(parts[1])
        if lim[6] > 0.0:
            fx = _objective(x, n1, positions, f, w, seg, thr, c2, c3, spring, even, scale,
                            lim, lam, mu, gbuf, pgrad, g, parts)
        else:
            fx /= scale
            for k in range(nv):
                g[k] /= scale
    nfev = 1
    s_mem = np.zeros((m, nv))
    y_mem = np.zeros((m, nv))
    rho = np.zeros(m)
    alpha = np.zeros(m)
    count = 0
    head = 0
    free = np.zeros(nv)
    d = np.zeros(nv)
    xn = np.zeros(nv)
    gn = np.zeros(nv)
    tmp = np.zeros(nv)
    tmp2 = np.zeros(nv)
    cp = np.zeros(n1)
    dp = np.zeros(n1)
    nit = 0
    small = 0
    status = 3
    for _ in range(maxiter):
        pg = 0.0
        for k in range(nv):
            held = lo[k] >= hi[k] or (x[k] <= lo[k] and g[k] > 0.0) or (
                x[k] >= hi[k] and g[k] < 0.0)
            free[k] = 0.0 if held else 1.0
            if not held and abs(g[k]) > pg:
                pg = abs(g[k])
        if pg <= gtol:
            status = 1
            break
        # Two-loop recursion on the free components (d stays zero on the held ones).
        for k in range(nv):
            d[k] = g[k] * free[k]
        for i in range(count):
            slot = (head - 1 - i) % m
            a = 0.0
            for k in range(nv):
                a += s_mem[slot, k] * d[k]
            a *= rho[slot]
            alpha[slot] = a
            for k in range(nv):
                d[k] -= a * y_mem[slot, k] * free[k]
        if pre:
            _tri_solve(d, free, n1, tmp, cp, dp)
            if count > 0:
                last = (head - 1) % m
                for k in range(nv):
                    tmp2[k] = y_mem[last, k] * free[k]
                _tri_solve(tmp2, free, n1, xn, cp, dp)
                yy = 0.0
                for k in range(nv):
                    yy += tmp2[k] * xn[k]
                gamma = 1.0 / (rho[last] * yy) if yy > 0 else 1.0
            else:
                gamma = 1.0 / math.sqrt(_sum_squares(tmp))
            for k in range(nv):
                d[k] = tmp[k] * gamma
        else:
            if count > 0:
                last = (head - 1) % m
                yy = 0.0
                for k in range(nv):
                    yy += y_mem[last, k] * y_mem[last, k] * free[k]
                gamma = 1.0 / (rho[last] * yy) if yy > 0 else 1.0
            else:
                gamma = 1.0 / math.sqrt(_sum_squares(d))
            for k in range(nv):
                d[k] *= gamma
        for i in range(count - 1, -1, -1):
            slot = (head - 1 - i) % m
            b = 0.0
            for k in range(nv):
                b += y_mem[slot, k] * d[k]
            b *= rho[slot]
            for k in range(nv):
                d[k] += (alpha[slot] - b) * s_mem[slot, k] * free[k]
        gd = 0.0
        for k in range(nv):
            d[k] = -d[k]
            gd += g[k] * d[k]
        if not gd < 0.0:
            # Not a descent direction (stale curvature): restart from steepest descent.
            count = 0
            norm = 0.0
            for k in range(nv):
                d[k] = -g[k] * free[k]
                norm += d[k] * d[k]
            norm = math.sqrt(norm)
            gd = 0.0
            for k in range(nv):
                d[k] /= norm
                gd += g[k] * d[k]
        # At most max_step [m] of any vertex per iteration: a longer step can carry a
        # vertex across a threat's core, which the line search, seeing only the end
        # point, would take when the penalty outweighs that threat's cost.
        step = 1.0
        longest = 0.0
        for k in range(0, nv, 3):
            longest = max(longest, d[k] * d[k] + d[k + 1] * d[k + 1] + d[k + 2] * d[k + 2])
        longest = math.sqrt(longest)
        if longest * step > max_step:
            step = max_step / longest
        full_step = step
        accepted = False
        fn = fx
        for _ in range(_MAX_BACKTRACKS):
            for k in range(nv):
                v = x[k] + step * d[k]
                xn[k] = lo[k] if v < lo[k] else hi[k] if v > hi[k] else v
            fn = _objective(xn, n1, positions, f, w, seg, thr, c2, c3, spring, even, scale,
                            lim, lam, mu, gbuf, pgrad, gn, trial)
            nfev += 1
            slope = 0.0
            for k in range(nv):
                slope += g[k] * (xn[k] - x[k])
            if fn <= fx + _ARMIJO * slope:
                accepted = True
                break
            # Minimiser of the quadratic through f(0), f'(0) and f(step), kept within
            # [0.1, 0.5] of the step (the projection bends the path: a safeguard).
            shrink = _BACKTRACK
            if fn < 1e299:
                curv = fn - fx - gd * step
                if curv > 0.0:
                    shrink = min(0.5, max(0.1, -gd * step / (2.0 * curv)))
            else:
                shrink = 0.1
            step *= shrink
        if not accepted:
            status = 2
            break
        nit += 1
        sy = 0.0
        yy = 0.0
        for k in range(nv):
            s_mem[head, k] = xn[k] - x[k]
            y_mem[head, k] = gn[k] - g[k]
            sy += s_mem[head, k] * y_mem[head, k]
            yy += y_mem[head, k] * y_mem[head, k]
        if sy > 1e-12 * yy and sy > 0.0:
            rho[head] = 1.0 / sy
            head = (head + 1) % m
            count = min(count + 1, m)
        decrease = (fx - fn) / max(abs(fx), abs(fn), 1.0)
        parts[:] = trial
        x[:] = xn
        g[:] = gn
        fx = fn
        if reach < math.inf:
            far = 0.0
            for k in range(0, nv, 3):
                far = max(far, (x[k] - x0[k]) ** 2 + (x[k + 1] - x0[k + 1]) ** 2
                          + (x[k + 2] - x0[k + 2]) ** 2)
            if far > reach * reach:
                status = 4
                break
        # A small decrease after a backtracked step says more about the step than about
        # the minimum: stop on the third in a row, or on one after a full step.
        small = small + 1 if decrease <= ftol else 0
        if small >= 3 or (decrease <= ftol and step == full_step):
            status = 0
            break
    out[:] = x
    return fx, nit, nfev, status


def objective(x, n1, positions, f, w, pairs, c2, c3, spring, even, scale, lim, lam, mu,
              gbuf, pgrad, grad) -> float:
    """Run :func:`_objective` (its arguments; ``pairs`` as in :func:`minimise`)."""
    with parallel_guard(len(pairs[0]) or (n1 - 1) * len(positions)):
        return float(_objective(x, n1, positions, f, w, pairs[0], pairs[1], c2, c3, spring,
                                even, scale, lim, lam, mu, gbuf, pgrad, grad, np.zeros(2)))


def minimise(x0, lo, hi, positions, f, w, pairs, c2, c3, spring, even, scale, lim, lam, mu,
             gbuf, pgrad, maxiter, ftol, gtol=1e-7, memory=20, max_step=math.inf,
             precondition=True, reach=math.inf, parts=None):
    """Run :func:`_minimise`; returns ``(x, value, iterations, evaluations)``.

    Parameters are those of the objective: ``x0``, ``lo``, ``hi`` flat (3 (n+1),) [m];
    ``pairs`` the (segment, threat) index arrays (empty: all pairs); ``lim`` the limit
    term's (sin climb, sin dive, min radius, climb on, dive on, radius on, term on);
    ``lam``, ``mu`` its multipliers and penalty; ``gbuf`` (rows,) and ``pgrad`` (n+1, 3)
    its scratch space; ``max_step`` the longest move of a vertex per iteration [m];
    ``precondition`` False for the plain identity-scaled start of the recursion; ``reach``
    how far a vertex may get from x0 before the run stops [m] (a cut-off's pairs hold
    only near where they were picked); ``scale`` <= 0 to scale by the start's value;
    ``parts`` (2,), if given, receives J + spring and J + both spacing terms at x, unscaled.
    """
    out = np.empty_like(x0)
    parts = np.zeros(2) if parts is None else parts
    with parallel_guard(len(pairs[0]) or (len(x0) // 3 - 1) * len(positions)):
        val, nit, nfev, _ = _minimise(x0, lo, hi, positions, f, float(w), pairs[0],
                                      pairs[1], c2, c3, float(spring), float(even),
                                      float(scale), lim, lam, float(mu), gbuf, pgrad,
                                      int(maxiter), float(ftol), float(gtol), int(memory),
                                      float(max_step), bool(precondition), float(reach),
                                      out, parts)
    return out, float(val), int(nit), int(nfev)
