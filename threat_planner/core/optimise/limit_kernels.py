"""Compiled (numba) flight-limit term of the augmented Lagrangian.

The same constraints as :func:`threat_planner.core.optimise.limits.constraint_values` (climb, dive,
fillet form of the turn radius, in that row order), fused with the Powell-Hestenes-
Rockafellar term so that one call gives the penalty's value and gradient (and, for SLSQP,
the values with their dense Jacobian). The numpy
version costs ~0.8 ms per evaluation at 40 segments (measured in
``bench/results/profile_before.txt``), more than J itself; this one costs microseconds.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from threat_planner.core.cost.kernels import njit

__all__ = ['LimitTerm', 'measure']

#: Floor of a segment length in a turn's terms: its square and products stay above zero.
_SHORT = 1e-150
#: Rounding of |u - v| = 2 sin(theta / 2) at a straight vertex, where the norm has a kink.
_EPS = 1e-9
#: Segments shorter than this fraction of the longest (or of 1 m) count as zero length.
DEGENERATE = 1e-12


@njit(cache=True)
def _dot3(a, b):
    """Return a . b of two 3-vectors, summed in one order (numba's ``@`` calls BLAS).

    See core/_vector.py.
    """
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _fillet(a, b, share):
    """Radius [m] of the arc tangent to segments a, b within ``share`` of their vertex.

    share / tan(theta / 2), theta the turn between them.
    """
    la = math.sqrt(_dot3(a, a))
    lb = math.sqrt(_dot3(b, b))
    cx = a[1] * b[2] - a[2] * b[1]
    cy = a[2] * b[0] - a[0] * b[2]
    cz = a[0] * b[1] - a[1] * b[0]
    cross = math.sqrt(cx * cx + cy * cy + cz * cz)
    # tan(theta / 2) = |a x b| / (|a| |b| + a . b): straight on 0, straight back inf.
    ab = _dot3(a, b)
    along = la * lb + ab
    if cross <= 1e-15 * la * lb:
        return math.inf if ab >= 0 else 0.0
    if along <= 0.0:
        return 0.0
    return share * along / cross


@njit(cache=True)
def _measure(points, floor_z):
    """Steepest climb and dive [deg], least turn radius [m], lowest interior altitude [m]."""
    n = points.shape[0] - 1
    climb = -90.0
    dive = -90.0
    longest = 1.0
    for s in range(n):
        dx = points[s + 1, 0] - points[s, 0]
        dy = points[s + 1, 1] - points[s, 1]
        dz = points[s + 1, 2] - points[s, 2]
        ang = math.degrees(math.atan2(dz, math.hypot(dx, dy)))
        climb = max(climb, ang)
        dive = max(dive, -ang)
        longest = max(longest, math.sqrt(dx * dx + dy * dy + dz * dz))
    # The fillet at each kept vertex, a vertex at the end of a zero-length segment skipped
    # over: the first and last kept segments are the start's and goal's in full.
    keep = np.empty(n + 1, np.int64)
    m = 1
    keep[0] = 0
    for s in range(n):
        d = points[s + 1] - points[s]
        if math.sqrt(_dot3(d, d)) > DEGENERATE * longest:
            keep[m] = s + 1
            m += 1
    radius = math.inf
    for k in range(1, m - 1):
        a = points[keep[k]] - points[keep[k - 1]]
        b = points[keep[k + 1]] - points[keep[k]]
        share = min(math.sqrt(_dot3(a, a)) * (1.0 if k == 1 else 0.5),
                    math.sqrt(_dot3(b, b)) * (1.0 if k == m - 2 else 0.5))
        radius = min(radius, _fillet(a, b, share))
    alt = math.inf
    for i in range(1, n):
        alt = min(alt, points[i, 2] - floor_z)
    return climb, dive, radius, alt


def measure(points: NDArray, floor_z: float) -> tuple[float, float, float, float]:
    """``(climb_deg, dive_deg, min_turn_radius_m, min_altitude_m)`` of a path (n+1, 3).

    The definitions of :mod:`.limits` (its module docstring), compiled.
    """
    return _measure(np.ascontiguousarray(points, float), float(floor_z))


@njit(cache=True)
def _half_turn(points, i, r_min, n, grad_out, want_grad):
    """Both radius rows of vertex i, (t |u + v| - |u - v|_eps) / 2, and their gradients.

    u, v are the unit segments a, b before and after the vertex and t = share / R_min of
    the segment before it (first row) or after it (second row), so a row is
    t cos(theta / 2) - sin(theta / 2): >= 0 exactly where tan(theta / 2) <= t. Its slope
    along the segment's length is alpha cos(theta / 2) / (2 R_min), which does not vanish
    as the segment shrinks (the squared form's did, and the penalty folded paths into
    zero-length segments it could not leave). With want_grad, grad_out rows 0-1 get
    dg/da, dg/db of the first row and rows 2-3 those of the second. Scalars throughout:
    small arrays made in a compiled loop cost more than the arithmetic.
    """
    ax = points[i, 0] - points[i - 1, 0]
    ay = points[i, 1] - points[i - 1, 1]
    az = points[i, 2] - points[i - 1, 2]
    bx = points[i + 1, 0] - points[i, 0]
    by = points[i + 1, 1] - points[i, 1]
    bz = points[i + 1, 2] - points[i, 2]
    la = max(math.sqrt(ax * ax + ay * ay + az * az), _SHORT)
    lb = max(math.sqrt(bx * bx + by * by + bz * bz), _SHORT)
    ux, uy, uz = ax / la, ay / la, az / la
    vx, vy, vz = bx / lb, by / lb, bz / lb
    px, py, pz = ux + vx, uy + vy, uz + vz
    mx, my, mz = ux - vx, uy - vy, uz - vz
    big_p = math.sqrt(px * px + py * py + pz * pz)
    big_m = math.sqrt(mx * mx + my * my + mz * mz + _EPS * _EPS)
    alpha_a = 1.0 if i == 1 else 0.5
    alpha_b = 1.0 if i == n - 1 else 0.5
    t_a = alpha_a * la / r_min
    t_b = alpha_b * lb / r_min
    sin_half = big_m - _EPS
    g_a = 0.5 * (t_a * big_p - sin_half)
    g_b = 0.5 * (t_b * big_p - sin_half)
    if want_grad:
        # d|p|/dp = p / |p| (0 at a hairpin), d|m|_eps/dm = m / |m|_eps,
        # du/da = (I - u u') / |a|, dv/db = (I - v v') / |b|.
        if big_p > _SHORT:
            qx, qy, qz = px / big_p, py / big_p, pz / big_p
        else:
            qx = qy = qz = 0.0
        hx, hy, hz = mx / big_m, my / big_m, mz / big_m
        for k in range(2):
            t = t_a if k == 0 else t_b
            wax, way, waz = t * qx - hx, t * qy - hy, t * qz - hz
            wbx, wby, wbz = t * qx + hx, t * qy + hy, t * qz + hz
            ua = ux * wax + uy * way + uz * waz
            vb = vx * wbx + vy * wby + vz * wbz
            ca = 0.5 * big_p * alpha_a / r_min if k == 0 else 0.0
            cb = 0.5 * big_p * alpha_b / r_min if k == 1 else 0.0
            grad_out[2 * k, 0] = 0.5 * (wax - ux * ua) / la + ca * ux
            grad_out[2 * k, 1] = 0.5 * (way - uy * ua) / la + ca * uy
            grad_out[2 * k, 2] = 0.5 * (waz - uz * ua) / la + ca * uz
            grad_out[2 * k + 1, 0] = 0.5 * (wbx - vx * vb) / lb + cb * vx
            grad_out[2 * k + 1, 1] = 0.5 * (wby - vy * vb) / lb + cb * vy
            grad_out[2 * k + 1, 2] = 0.5 * (wbz - vz * vb) / lb + cb * vz
    return g_a, g_b


@njit(cache=True)
def _values(points, sin_c, sin_d, r_min, on_c, on_d, on_r, out):
    """Constraint values g into out (climb rows, dive rows, radius rows, on ones only)."""
    n = points.shape[0] - 1
    row = 0
    for k in range(2):
        on = on_c if k == 0 else on_d
        if not on:
            continue
        sn = sin_c if k == 0 else sin_d
        cs = math.sqrt(1.0 - sn * sn)
        sign = -1.0 if k == 0 else 1.0
        for s in range(n):
            dx = points[s + 1, 0] - points[s, 0]
            dy = points[s + 1, 1] - points[s, 1]
            dz = points[s + 1, 2] - points[s, 2]
            ln = math.sqrt(dx * dx + dy * dy + dz * dz)
            h = math.sqrt(dx * dx + dy * dy)
            out[row] = (h * sn + sign * dz * cs) / (ln if ln > 0 else 1.0)
            row += 1
    if on_r:
        # Two rows a vertex (_half_turn), for the share of the segment before it (first
        # block) and of the one after it (second block).
        scratch = np.empty((4, 3))
        for i in range(1, n):
            out[row + i - 1], out[row + n - 2 + i] = _half_turn(points, i, r_min, n, scratch,
                                                                False)
        row += 2 * (n - 1)
    return row


@njit(cache=True)
def _axis(points):
    """Horizontal direction of a vertical segment: the start-goal one (as limits._blocks)."""
    n = points.shape[0] - 1
    ux = points[n, 0] - points[0, 0]
    uy = points[n, 1] - points[0, 1]
    un = math.sqrt(ux * ux + uy * uy)
    return (ux / un, uy / un) if un > 0 else (1.0, 0.0)


@njit(cache=True)
def _slope_gradient(points, s_, sn, cs, sign, ux, uy):
    """dg/dd of segment s_'s climb (sign -1) or dive (+1) row, and whether |d| > 0.

    dg/dd = sin dh/dd / |d| - g d / |d|^2 + sign cos e_z / |d|, with |d| taken as 1 for a
    zero-length segment.
    """
    dx = points[s_ + 1, 0] - points[s_, 0]
    dy = points[s_ + 1, 1] - points[s_, 1]
    dz = points[s_ + 1, 2] - points[s_, 2]
    ln = math.sqrt(dx * dx + dy * dy + dz * dz)
    positive = ln > 0
    ln = ln if positive else 1.0
    h = math.sqrt(dx * dx + dy * dy)
    hx, hy = (dx / h, dy / h) if h > 0 else (ux, uy)
    gv = (h * sn + sign * dz * cs) / ln
    return (sn * hx / ln - gv * dx / (ln * ln), sn * hy / ln - gv * dy / (ln * ln),
            sign * cs / ln - gv * dz / (ln * ln), positive)


@njit(cache=True)
def _penalty(points, sin_c, sin_d, r_min, on_c, on_d, on_r, lam, mu, g, grad):
    """PHR term sum(s^2 - lam^2) / (2 mu), s = max(0, lam - mu g); gradient into grad."""
    m = _values(points, sin_c, sin_d, r_min, on_c, on_d, on_r, g)
    n = points.shape[0] - 1
    grad[:, :] = 0.0
    val = 0.0
    for k in range(m):
        s = lam[k] - mu * g[k]
        s = s if s > 0.0 else 0.0
        val += s * s - lam[k] * lam[k]
        # d/dx of the term is -s dg/dx; keep s in g's slot for the passes below.
        g[k] = s
    ux, uy = _axis(points)
    row = 0
    for k in range(2):
        on = on_c if k == 0 else on_d
        if not on:
            continue
        sn = sin_c if k == 0 else sin_d
        cs = math.sqrt(1.0 - sn * sn)
        sign = -1.0 if k == 0 else 1.0
        for s_ in range(n):
            s = g[row]
            row += 1
            if s == 0.0:
                continue
            fx, fy, fz, positive = _slope_gradient(points, s_, sn, cs, sign, ux, uy)
            if not positive:
                continue
            # The term's gradient is -s dg/dd at the segment's end, +s dg/dd at its start.
            grad[s_ + 1, 0] -= s * fx
            grad[s_ + 1, 1] -= s * fy
            grad[s_ + 1, 2] -= s * fz
            grad[s_, 0] += s * fx
            grad[s_, 1] += s * fy
            grad[s_, 2] += s * fz
    if on_r:
        dg = np.empty((4, 3))
        for i in range(1, n):
            s_a = g[row + i - 1]
            s_b = g[row + n - 2 + i]
            if s_a == 0.0 and s_b == 0.0:
                continue
            _half_turn(points, i, r_min, n, dg, True)
            # The term's gradient is -s dg/dx; a = x_i - x_(i-1), b = x_(i+1) - x_i.
            for k in range(3):
                da = s_a * dg[0, k] + s_b * dg[2, k]
                db = s_a * dg[1, k] + s_b * dg[3, k]
                grad[i - 1, k] += da
                grad[i, k] -= da - db
                grad[i + 1, k] -= db
    return val / (2.0 * mu), m


@njit(cache=True)
def _jacobian(points, sin_c, sin_d, r_min, on_c, on_d, on_r, g, jac):
    """Constraint values g into g and their dense Jacobian dg/dx into jac (rows, n+1, 3).

    The rows of :func:`_values`; the derivatives of :func:`_penalty` (there multiplied by
    the multipliers), so SLSQP sees the same constraints as the augmented Lagrangian.
    """
    m = _values(points, sin_c, sin_d, r_min, on_c, on_d, on_r, g)
    n = points.shape[0] - 1
    jac[:, :, :] = 0.0
    ux, uy = _axis(points)
    row = 0
    for k in range(2):
        on = on_c if k == 0 else on_d
        if not on:
            continue
        sn = sin_c if k == 0 else sin_d
        cs = math.sqrt(1.0 - sn * sn)
        sign = -1.0 if k == 0 else 1.0
        for s_ in range(n):
            r = row
            row += 1
            # A zero-length segment keeps its subgradient (limits._blocks' too), not a zero
            # row, which SLSQP would read as a constraint it cannot move.
            fx, fy, fz, _ = _slope_gradient(points, s_, sn, cs, sign, ux, uy)
            jac[r, s_ + 1, 0] = fx
            jac[r, s_ + 1, 1] = fy
            jac[r, s_ + 1, 2] = fz
            jac[r, s_, 0] = -fx
            jac[r, s_, 1] = -fy
            jac[r, s_, 2] = -fz
    if on_r:
        dg = np.empty((4, 3))
        for i in range(1, n):
            _half_turn(points, i, r_min, n, dg, True)
            # a = x_i - x_(i-1), b = x_(i+1) - x_i: dg/dx_(i-1) = -dg/da,
            # dg/dx_i = dg/da - dg/db, dg/dx_(i+1) = dg/db.
            for blk in range(2):
                r = row + i - 1 if blk == 0 else row + n - 2 + i
                for c in range(3):
                    da = dg[2 * blk, c]
                    db = dg[2 * blk + 1, c]
                    jac[r, i - 1, c] = -da
                    jac[r, i, c] = da - db
                    jac[r, i + 1, c] = db
    return m


class LimitTerm:
    """Augmented Lagrangian term of the flight limits for paths of a fixed vertex count.

    Parameters
    ----------
    limits : FlightLimits
        The limits the term enforces (the optimiser passes its tightened aim).
    vertices : int
        Vertices of the paths it will see.

    """

    def __init__(self, limits, vertices: int) -> None:
        self.args = (math.sin(math.radians(limits.max_climb_deg)),
                     math.sin(math.radians(limits.max_dive_deg)),
                     float(limits.min_turn_radius_m), limits.climb_on, limits.dive_on,
                     limits.radius_on and vertices >= 3)
        self.vertices = vertices
        n = vertices - 1
        radius_rows = 2 * max(n - 1, 0) if self.args[5] else 0
        self.rows = (limits.climb_on + limits.dive_on) * n + radius_rows
        self._g = np.zeros(self.rows)
        self._grad = np.zeros((vertices, 3))

    def transfer(self, coarse: tuple['LimitTerm', NDArray]) -> NDArray:
        """Multipliers of this term from those of the same limits on a coarser path.

        A multiplier is the density of the continuous one times the spacing (its row's
        share of the path), so it is interpolated along the path's parameter and scaled
        by the ratio of the segment counts.
        """
        term, lam = coarse
        nc, nf = term.vertices - 1, self.vertices - 1
        out = np.zeros(self.rows)
        seg_c, seg_f = (np.arange(nc) + 0.5) / nc, (np.arange(nf) + 0.5) / nf
        ver_c, ver_f = np.arange(1, nc) / nc, np.arange(1, nf) / nf
        rc = rf = 0
        # Rows: climb (segments), dive (segments), radius (vertices, twice: two blocks).
        blocks = ((seg_c, seg_f), (seg_c, seg_f), (ver_c, ver_f), (ver_c, ver_f))
        for on, (uc, uf) in zip((*self.args[3:], self.args[5]), blocks):
            if not on:
                continue
            if len(uf) and len(uc):
                out[rf:rf + len(uf)] = np.interp(uf, uc, lam[rc:rc + len(uc)]) * nc / nf
            rc, rf = rc + len(uc), rf + len(uf)
        return out

    def kernel_args(self) -> NDArray:
        """Return the term as :func:`.lbfgs.minimise` takes it, (7,)."""
        return np.array([*self.args[:3], *(float(flag) for flag in self.args[3:]), 1.0])

    def values(self, points: NDArray) -> NDArray:
        """Constraint values g (>= 0 where the limits hold), (rows,)."""
        out = np.zeros(self.rows)
        _values(np.ascontiguousarray(points, float), *self.args, out)
        return out

    def values_jacobian(self, points: NDArray) -> tuple[NDArray, NDArray]:
        """Constraint values g (rows,) and the dense Jacobian dg/dx (rows, vertices, 3)."""
        g = np.zeros(self.rows)
        jac = np.zeros((self.rows, self.vertices, 3))
        _jacobian(np.ascontiguousarray(points, float), *self.args, g, jac)
        return g, jac

    def penalty(self, points: NDArray, lam: NDArray, mu: float) -> tuple[float, NDArray]:
        """PHR term and its gradient over every vertex, (vertices, 3) (a view, reused)."""
        val, _ = _penalty(np.ascontiguousarray(points, float), *self.args, lam, float(mu),
                          self._g, self._grad)
        return float(val), self._grad
