"""Trajectory cost J = w*J_R + (1-w)*J_L (paper Section IV, eq. 15-17), in closed form.

Convention (the project's, documented in the README):

* J_L is the polyline's length (eq. 16).
* J_R is the sum over segments and threats of ``F_i * integral ds / |x(s) - p_i|^4`` along
  the segment, ``s`` being arc length. The paper's eq. 17 omits the intensity F_i and
  multiplies the integral by the segment length L a second time; we weight by F_i (the
  radar equation, eq. 3) and integrate over arc length once, so J_R is independent of how a
  straight flight is split into segments.

For a segment with unit direction u, the threat's foot point on the segment's line splits
the segment at signed abscissae t1 < t2 (t2 - t1 = L) and lies at distance h from the
threat, so the integrand is 1/(t^2 + h^2)^2. Its antiderivative has an atan part of size
1/h^3 that cancels between the two ends when both lie on the same side of the foot point;
near-line threats (h -> 0) would lose every digit to that cancellation, so each end's
antiderivative is split into an exact multiple of pi/(4 h^3), cancelled symbolically, and a
remainder evaluated by a series where it is small. The same split gives the 1/(t^2+h^2)^3
moment used by the analytic gradient.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from threat_planner.core._vector import rows_dot

#: Pairs evaluated at once by the pair-wise costs.
PAIR_CHUNK = 262_144
#: Threats whose closest approach to a segment is below this are treated as hit [m].
CONTACT_DISTANCE = 1e-9

# Below this ratio h/|t| the remainders use their power series (see _far_remainders).
_SERIES_LIMIT = 0.1
_N_TERMS = 8
_n = np.arange(1, _N_TERMS + 1)
# (atan x - x/(1+x^2)) / x^3 = sum_{n>=1} (-1)^(n+1) 2n/(2n+1) x^(2n-2)
_C2 = ((-1.0) ** (_n + 1)) * 2 * _n / (2 * _n + 1)
_m = np.arange(2, _N_TERMS + 2)
# (3/8 atan x - 3/8 x/(1+x^2) - 1/4 x^3/(1+x^2)^2) / x^5
#   = sum_{n>=2} (-1)^n n(n-1) / (2(2n+1)) x^(2n-4)
_C3 = ((-1.0) ** _m) * _m * (_m - 1) / (2 * (2 * _m + 1))


@dataclass(frozen=True)
class Cost:
    """The three numbers that score a path.

    Attributes:
        J: Weighted total w*J_R + (1-w)*J_L.
        J_L: Length cost [m].
        J_R: Threat cost [intensity * m^-3].
    """

    J: float
    J_L: float
    J_R: float

    def as_dict(self) -> dict[str, float]:
        """Return ``{"J": ..., "J_L": ..., "J_R": ...}``."""
        return {'J': self.J, 'J_L': self.J_L, 'J_R': self.J_R}


def _series(x2: NDArray, coeffs: NDArray) -> NDArray:
    """Evaluate sum_k coeffs[k] * x2**k by Horner's rule."""
    out = np.full_like(x2, coeffs[-1])
    for c in coeffs[-2::-1]:
        out = out * x2 + c
    return out


def _antiderivatives(t: NDArray, h: NDArray, moment: bool = True
                     ) -> tuple[NDArray, NDArray, NDArray | None]:
    """Split antiderivatives of 1/(t^2+h^2)^2 and 1/(t^2+h^2)^3 at abscissa t.

    Returns ``(c, r2, r3)`` such that the antiderivatives are ``c*pi/(4 h^3) + r2`` and
    ``c*3pi/(16 h^5) + r3``, where c = sign(t) for |t| > h and 0 otherwise. Differences of c
    are then exact integers, so the large terms cancel without rounding. With
    ``moment=False`` the second (needed only for gradients) is skipped and r3 is None.
    """
    abs_t = np.abs(t)
    far = abs_t > h
    c = np.where(far, np.sign(t), 0.0)
    r2 = np.empty_like(t)
    r3 = np.empty_like(t) if moment else None

    # Near the foot point, the plain antiderivative in r = t/h is well conditioned.
    near = ~far
    if np.any(near):
        hn = h[near]
        # h = 0 here means an end on the threat itself; _integrals marks that pair infinite.
        hn = np.where(hn > 0, hn, np.inf)
        r = t[near] / hn
        q = 1.0 / (1.0 + r * r)
        at = np.arctan(r)
        r2[near] = (at + r * q) / (2.0 * hn ** 3)
        if moment:
            r3[near] = (0.375 * at + 0.375 * r * q + 0.25 * r * q * q) / hn ** 5

    # Far from it, write atan(t/h) = sign(t) pi/2 - atan(h/t) and keep only the remainder,
    # which behaves like -1/(3 t^3) and -1/(5 t^5).
    if np.any(far):
        tf = abs_t[far]
        x = h[far] / tf
        x2 = x * x
        small = x < _SERIES_LIMIT
        g2 = np.empty_like(x)
        g3 = np.empty_like(x) if moment else None
        g2[small] = _series(x2[small], _C2)
        if moment:
            g3[small] = _series(x2[small], _C3)
        big = ~small
        if np.any(big):
            xb = x[big]
            qb = 1.0 / (1.0 + xb * xb)
            at = np.arctan(xb)
            g2[big] = (at - xb * qb) / xb ** 3
            if moment:
                g3[big] = (0.375 * at - 0.375 * xb * qb - 0.25 * xb ** 3 * qb * qb) / xb ** 5
        s = np.sign(t[far])
        r2[far] = -s * g2 / (2.0 * tf ** 3)
        if moment:
            r3[far] = -s * g3 / tf ** 5
    return c, r2, r3


@dataclass(frozen=True)
class _Geometry:
    """Geometry of (segment, threat) pairs, broadcast to a common shape ``P``."""

    length: NDArray      # P, segment lengths
    u: NDArray           # P x 3, unit directions
    t1: NDArray          # P, abscissa of the segment start from the foot point
    t2: NDArray          # P
    h: NDArray           # P, distance from the threat to the segment's line
    perp: NDArray        # P x 3, foot point minus threat


def _geometry(a: NDArray, b: NDArray, p: NDArray) -> _Geometry:
    """Pair geometry; a, b and p broadcast against each other (last axis xyz)."""
    d = b - a
    length = np.linalg.norm(d, axis=-1)
    u = d / np.where(length > 0, length, 1.0)[..., None]
    e = a - p
    t1 = np.sum(e * u, axis=-1)
    perp = e - t1[..., None] * u
    h = np.linalg.norm(perp, axis=-1)
    shape = h.shape
    length = np.broadcast_to(length, shape)
    return _Geometry(length, np.broadcast_to(u, shape + (3,)), t1, t1 + length, h, perp)


def segment_integrals(a: NDArray, b: NDArray, positions: NDArray) -> NDArray:
    """Closed-form integral of ds / |x(s) - p|^4 over each segment for each threat.

    Args:
        a: Segment starts, shape (S, 3) [m].
        b: Segment ends, shape (S, 3) [m].
        positions: Threat positions, shape (N, 3) [m].

    Returns:
        Array (S, N) of integrals [m^-3] (not yet weighted by intensity); ``inf`` where a
        segment passes within CONTACT_DISTANCE of a threat, 0 for zero-length segments.
    """
    a = np.asarray(a, float)[:, None, :]
    b = np.asarray(b, float)[:, None, :]
    return _integrals(_geometry(a, b, np.asarray(positions, float)[None, :, :]), False)[0]


def pair_integrals(a: NDArray, b: NDArray, p: NDArray) -> NDArray:
    """Closed-form integral of ds / |x(s) - p|^4 for matched (segment, threat) pairs.

    Args:
        a: Segment starts, shape (P, 3) [m].
        b: Segment ends, shape (P, 3) [m].
        p: Threat positions, shape (P, 3) [m].

    Returns:
        Array (P,) of integrals [m^-3].
    """
    return _integrals(_geometry(np.asarray(a, float), np.asarray(b, float),
                                np.asarray(p, float)), False)[0]


def _integrals(g: _Geometry, moment: bool = True) -> tuple[NDArray, NDArray | None]:
    """Return the integrals of 1/d^4 and (if ``moment``) of 1/d^6 along each segment."""
    h = g.h
    # Both ends in one call: half the numpy calls, which dominate on small problems.
    c, r2, r3 = _antiderivatives(np.stack([g.t1, g.t2]), np.stack([h, h]), moment)
    dc = c[1] - c[0]
    # A threat on the segment itself (h ~ 0 with the foot point inside) costs infinity.
    hit = (h < CONTACT_DISTANCE) & (g.t1 <= CONTACT_DISTANCE) & (g.t2 >= -CONTACT_DISTANCE)
    zero = g.length == 0
    with np.errstate(divide='ignore', invalid='ignore'):
        big2 = np.where(dc != 0, dc * (np.pi / 4.0) / h ** 3, 0.0)
        i2 = np.where(zero, 0.0, np.where(hit, np.inf, big2 + (r2[1] - r2[0])))
        if not moment:
            return i2, None
        big3 = np.where(dc != 0, dc * (3.0 * np.pi / 16.0) / h ** 5, 0.0)
        i3 = np.where(zero, 0.0, np.where(hit, np.inf, big3 + (r3[1] - r3[0])))
    return i2, i3


def segment_threat_costs(a: NDArray, b: NDArray, positions: NDArray,
                         intensities: NDArray, chunk: int = 2_000_000) -> NDArray:
    """Threat cost of each segment, sum_i F_i * integral ds/d^4 (eq. 17, our convention).

    Args:
        a: Segment starts, shape (S, 3) [m].
        b: Segment ends, shape (S, 3) [m].
        positions: Threat positions, shape (N, 3) [m].
        intensities: Threat intensities F, shape (N,).
        chunk: Largest number of (segment, threat) pairs evaluated at once, to bound memory.

    Returns:
        Array (S,) of threat costs.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    positions = np.asarray(positions, float)
    intensities = np.asarray(intensities, float)
    n = len(positions)
    out = np.zeros(len(a))
    if n == 0 or len(a) == 0:
        return out
    step = max(1, chunk // n)
    for s in range(0, len(a), step):
        out[s:s + step] = rows_dot(
            segment_integrals(a[s:s + step], b[s:s + step], positions), intensities)
    return out


def path_cost(points: NDArray, positions: NDArray, intensities: NDArray, w: float) -> Cost:
    """Cost J of a polyline (eq. 15), with J_L (eq. 16) and closed-form J_R (eq. 17).

    Args:
        points: Polyline vertices, shape (n, 3) [m].
        positions: Threat positions, shape (N, 3) [m].
        intensities: Threat intensities F, shape (N,).
        w: Threat weight, 0 < w < 1.

    Returns:
        The path's Cost.
    """
    points = np.asarray(points, float)
    j_l = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    j_r = float(np.sum(segment_threat_costs(points[:-1], points[1:], positions, intensities)))
    return Cost(w * j_r + (1.0 - w) * j_l, j_l, j_r)


def _pair_gradient(g: _Geometry, f: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Weighted integrals F*I of each pair and their gradients at the segment's two ends.

    With D the foot point minus the threat, phi_k = 1/|end_k - p|^4 and M0 the integral of
    1/d^6, the segment integral I(t1, t2, h^2) has dI/dt2 = phi_b, dI/dt1 = -phi_a and
    dI/d(h^2) = -2 M0; with dt1/da = u - D/L, dt2/da = -D/L, d(h^2)/da = 2D(1 + t1/L) and
    their counterparts at b this gives the exact gradient.
    """
    i2, i3 = _integrals(g)
    ok = g.length > 0
    inv_l = np.where(ok, 1.0 / np.where(ok, g.length, 1.0), 0.0)
    # A pair on a threat has infinite cost; callers test the cost, so its NaN gradient
    # needs no warning.
    with np.errstate(divide='ignore', invalid='ignore'):
        phi_a = np.where(ok, f / (g.t1 ** 2 + g.h ** 2) ** 2, 0.0)
        phi_b = np.where(ok, f / (g.t2 ** 2 + g.h ** 2) ** 2, 0.0)
        m0 = i3 * f
        coef_d_a = (phi_a - phi_b) * inv_l - 4.0 * m0 * (1.0 + g.t1 * inv_l)
        coef_d_b = (phi_b - phi_a) * inv_l + 4.0 * m0 * g.t1 * inv_l
        da = coef_d_a[..., None] * g.perp - phi_a[..., None] * g.u
        db = coef_d_b[..., None] * g.perp + phi_b[..., None] * g.u
    return i2 * f, da, db


def _dense_gradient(a: NDArray, b: NDArray, positions: NDArray, f: NDArray
                    ) -> tuple[float, NDArray, NDArray]:
    """J_R and its gradient at segment starts and ends, every segment with every threat.

    The same mathematics as _pair_gradient, with the sums over threats of the D terms
    written as matrix products (D = a - p - t1 u), so no (S, N, 3) array is formed: this
    runs inside the optimiser's every evaluation.
    """
    d = b - a
    length = np.sqrt(np.einsum('sk,sk->s', d, d))
    ok = length > 0
    inv_l = np.where(ok, 1.0 / np.where(ok, length, 1.0), 0.0)
    u = d * inv_l[:, None]
    ex = a[:, 0:1] - positions[None, :, 0]
    ey = a[:, 1:2] - positions[None, :, 1]
    ez = a[:, 2:3] - positions[None, :, 2]
    ux, uy, uz = u[:, 0:1], u[:, 1:2], u[:, 2:3]
    t1 = ex * ux + ey * uy + ez * uz
    cx = ey * uz - ez * uy
    cy = ez * ux - ex * uz
    cz = ex * uy - ey * ux
    h = np.sqrt(cx * cx + cy * cy + cz * cz)
    lcol = length[:, None]
    g = _Geometry(np.broadcast_to(lcol, h.shape), None, t1, t1 + lcol, h, None)
    i2, i3 = _integrals(g)
    j_r = float(rows_dot(i2, f).sum())
    if not np.isfinite(j_r):
        zero = np.zeros_like(a)
        return j_r, zero, zero
    okc = ok[:, None]
    il = inv_l[:, None]
    # Intensities near the float limit overflow here although J itself did not; the
    # caller sees J and such a gradient only steers a search that will be refused anyway.
    with np.errstate(over='ignore', invalid='ignore'):
        phi_a = np.where(okc, f / (ex * ex + ey * ey + ez * ez) ** 2, 0.0)
        fx, fy, fz = ex + d[:, 0:1], ey + d[:, 1:2], ez + d[:, 2:3]
        phi_b = np.where(okc, f / (fx * fx + fy * fy + fz * fz) ** 2, 0.0)
        m0 = i3 * f
        coef_a = (phi_a - phi_b) * il - 4.0 * m0 * (1.0 + t1 * il)
        coef_b = (phi_b - phi_a) * il + 4.0 * m0 * t1 * il

    def along_d(coef: NDArray) -> NDArray:
        # sum_n coef * (a - p_n - t1 u) without forming the (S, N, 3) array
        return (a * coef.sum(axis=1)[:, None] - rows_dot(coef, positions)
                - (coef * t1).sum(axis=1)[:, None] * u)

    with np.errstate(over='ignore', invalid='ignore'):
        da = along_d(coef_a) - phi_a.sum(axis=1)[:, None] * u
        db = along_d(coef_b) + phi_b.sum(axis=1)[:, None] * u
    return j_r, da, db


def threat_cost_and_gradient(points: NDArray, positions: NDArray, intensities: NDArray,
                             pairs: tuple[NDArray, NDArray] | None = None
                             ) -> tuple[float, NDArray]:
    """J_R of a polyline and its exact gradient with respect to every vertex.

    Args:
        points: Polyline vertices, shape (n, 3) [m].
        positions: Threat positions, shape (N, 3) [m].
        intensities: Threat intensities F, shape (N,).
        pairs: Optional ``(segment_index, threat_index)`` arrays restricting the sum to
            those pairs (a cut-off, see ``ThreatField.near_pairs``); all pairs if None.

    Returns:
        ``(J_R, grad)`` with grad of shape (n, 3).
    """
    points = np.asarray(points, float)
    positions = np.asarray(positions, float)
    f = np.asarray(intensities, float)
    a, b = points[:-1], points[1:]
    grad = np.zeros_like(points)
    if len(positions) == 0:
        return 0.0, grad
    if pairs is None:
        j_r, da, db = _dense_gradient(a, b, positions, f)
    else:
        seg, thr = pairs
        cost, da_p, db_p = _pair_gradient(_geometry(a[seg], b[seg], positions[thr]), f[thr])
        j_r = float(cost.sum())
        da = np.stack([np.bincount(seg, da_p[:, k], len(a)) for k in range(3)], axis=1)
        db = np.stack([np.bincount(seg, db_p[:, k], len(a)) for k in range(3)], axis=1)
    if not np.isfinite(j_r):
        return j_r, grad
    grad[:-1] += da
    grad[1:] += db
    return j_r, grad


def cost_and_gradient(points: NDArray, positions: NDArray, intensities: NDArray, w: float,
                      pairs: tuple[NDArray, NDArray] | None = None) -> tuple[float, NDArray]:
    """J of a polyline (eq. 15) and its gradient with respect to every vertex.

    Args:
        points: Polyline vertices, shape (n, 3) [m].
        positions: Threat positions, shape (N, 3) [m].
        intensities: Threat intensities F, shape (N,).
        w: Threat weight, 0 < w < 1.
        pairs: Optional cut-off pairs, as in threat_cost_and_gradient.

    Returns:
        ``(J, grad)`` with grad of shape (n, 3).
    """
    points = np.asarray(points, float)
    j_r, g_r = threat_cost_and_gradient(points, positions, intensities, pairs)
    d = np.diff(points, axis=0)
    seg = np.linalg.norm(d, axis=1)
    unit = d / np.where(seg > 0, seg, 1.0)[:, None]
    g_l = np.zeros_like(points)
    g_l[:-1] -= unit
    g_l[1:] += unit
    return w * j_r + (1.0 - w) * float(seg.sum()), w * g_r + (1.0 - w) * g_l


def pair_threat_costs(a: NDArray, b: NDArray, positions: NDArray, intensities: NDArray,
                      seg: NDArray, thr: NDArray) -> NDArray:
    """Threat cost of each segment summed over the given (segment, threat) pairs only.

    Args:
        a: Segment starts, shape (S, 3) [m].
        b: Segment ends, shape (S, 3) [m].
        positions: Threat positions, shape (N, 3) [m].
        intensities: Threat intensities F, shape (N,).
        seg: Segment index of each pair, shape (P,).
        thr: Threat index of each pair, shape (P,).

    Returns:
        Array (S,) of threat costs over the pairs given.
    """
    out = np.zeros(len(a))
    # Chunks bound the temporaries (about 40 doubles per pair) to a few hundred MB.
    for lo in range(0, len(seg), PAIR_CHUNK):
        s, t = seg[lo:lo + PAIR_CHUNK], thr[lo:lo + PAIR_CHUNK]
        vals = pair_integrals(a[s], b[s], positions[t]) * intensities[t]
        out += np.bincount(s, vals, len(a))
    return out
