"""Compiled (numba) closed form of one (segment, threat) pair: integrals of ds / d^n.

What every compiled cost shares (:mod:`.kernels`' J, gradient and segment costs,
:mod:`.near_kernels`' cut-off costs): the foot of the perpendicular from a threat to a
segment's line, and from it I2, the integral of ds / d^4 (the pair's J_R over F, eq. 17
in our convention), and I3, that of ds / d^6 (in its gradient). Two forms, by where the
ends lie along the line:

* :func:`_direct`, both ends within ``1 / _SERIES_LIMIT`` distances of the foot (nearly
  every pair of a plan): the two atan terms' difference is one atan of the angle the
  segment subtends, and the rational parts share two reciprocals;
* :func:`_far`, otherwise: :mod:`.cost`'s split antiderivatives (each large atan term
  cancelled symbolically) and, far along the line, their power series.

:func:`_direct` made the 40-segment, 20-threat J and gradient 35.7 -> 22.2 us (the two atan
and about ten divisions per pair of :func:`_far` before; ``bench/results/
profile_kernel.txt``). Importing this module points numba's cache at
:mod:`._numba_cache`, or, where an AOT module fits these sources, makes ``njit`` record
the functions for :mod:`._aot`; without numba they run as plain Python (correct, slow).
"""

from __future__ import annotations

import math

from threat_planner.core import _aot

try:
    if _aot.module() is not None:
        # The AOT module replaces the kernels (_aot.install): no numba import, plain
        # functions recorded for it and for the lazily built JIT kernels of large problems.
        HAVE_NUMBA = True
        prange = range
        njit = _aot.stub_njit
    else:
        from numba import njit, prange
        HAVE_NUMBA = True
        from threat_planner.core import _numba_cache
        _numba_cache.configure()
except ImportError:  # pragma: no cover - numba is in install_requires
    HAVE_NUMBA = False
    prange = range

    def njit(*args, **kwargs):  # noqa: D103
        if args and callable(args[0]):
            return args[0]
        return lambda fn: fn

from threat_planner.core.cost.closed_form import _SERIES_LIMIT, CONTACT_DISTANCE

__all__ = ['HAVE_NUMBA', 'njit', 'prange']

_PI = math.pi


@njit(cache=True, inline='always')
def _horner(x2, coeffs):
    out = coeffs[-1]
    for k in range(len(coeffs) - 2, -1, -1):
        out = out * x2 + coeffs[k]
    return out


@njit(cache=True, inline='always')
def _split(t, h, c2, c3):
    """(c, r2, r3) of cost._antiderivatives for one abscissa t and distance h."""
    abs_t = abs(t)
    if abs_t > h:
        s = 1.0 if t > 0 else -1.0
        x = h / abs_t
        if x < _SERIES_LIMIT:
            x2 = x * x
            g2 = _horner(x2, c2)
            g3 = _horner(x2, c3)
        else:
            q = 1.0 / (1.0 + x * x)
            at = math.atan(x)
            g2 = (at - x * q) / x ** 3
            g3 = (0.375 * at - 0.375 * x * q - 0.25 * x ** 3 * q * q) / x ** 5
        return s, -s * g2 / (2.0 * abs_t ** 3), -s * g3 / abs_t ** 5
    hn = h if h > 0 else math.inf
    r = t / hn
    q = 1.0 / (1.0 + r * r)
    at = math.atan(r)
    return (0.0, (at + r * q) / (2.0 * hn ** 3),
            (0.375 * at + 0.375 * r * q + 0.25 * r * q * q) / hn ** 5)


@njit(cache=True, inline='always')
def _far(t1, t2, h, c2, c3):
    """(I2, I3) as :func:`_direct` from the split antiderivatives (any t1 < t2, h >= 0).

    Each end's large atan term is cancelled symbolically, and beyond ``1 / _SERIES_LIMIT``
    distances from the foot its remainder is a power series: the form for ends far along
    the line, where :func:`_direct`'s two parts would cancel.
    """
    ca, r2a, r3a = _split(t1, h, c2, c3)
    cb, r2b, r3b = _split(t2, h, c2, c3)
    dc = cb - ca
    i2 = r2b - r2a
    i3 = r3b - r3a
    if dc != 0:
        i2 += dc * (_PI / 4.0) / h ** 3
        i3 += dc * (3.0 * _PI / 16.0) / h ** 5
    return i2, i3


#: Ends within this many distances of the foot take :func:`_direct` (beyond, the series).
_DIRECT_REACH = 1.0 / _SERIES_LIMIT


@njit(cache=True, inline='always')
def _direct(t1, t2, h, h2, ln, ida, idb):
    """(I2, I3): integrals of ds / d^4 and ds / d^6 from t1 to t2 = t1 + ln at distance h.

    ``ida``, ``idb`` are 1 / (h^2 + t^2) at the ends. With theta the angle the segment
    subtends at the threat (atan(t2/h) - atan(t1/h), one atan),
    I2 = ([t / d] + theta / h) / (2 h^2) and I3 = [t / d^2] / (4 h^2) + 3 I2 / (4 h^2).
    For |t| <= _DIRECT_REACH h the two parts of I2 cancel by at most ~2 digits.
    """
    den = h2 + t1 * t2
    ih = 1.0 / h
    if den > 0.0:
        theta = math.atan(h * ln / den)
    elif den < 0.0:
        theta = _PI - math.atan(h * ln / -den)
    else:
        theta = 0.5 * _PI
    ih2 = ih * ih
    ra = t1 * ida
    rb = t2 * idb
    d1 = rb - ra + theta * ih
    return 0.5 * ih2 * d1, ih2 * (0.25 * (rb * idb - ra * ida) + 0.375 * ih2 * d1)


@njit(cache=True, inline='always')
def _foot(ax, ay, az, ux, uy, uz, ln, positions, i):
    """Threat i against the segment of length ln [m] from (ax, ay, az) along unit u.

    Returns ``(t1, t2, px, py, pz, h2, h, hit)``: the segment's ends along its line from
    the foot of the perpendicular, the threat-to-line offset p, |p|^2 and |p|, and whether
    the segment passes within CONTACT_DISTANCE of the threat.
    """
    ex = ax - positions[i, 0]
    ey = ay - positions[i, 1]
    ez = az - positions[i, 2]
    t1 = ex * ux + ey * uy + ez * uz
    t2 = t1 + ln
    px, py, pz = ex - t1 * ux, ey - t1 * uy, ez - t1 * uz
    h2 = px * px + py * py + pz * pz
    h = math.sqrt(h2)
    hit = h < CONTACT_DISTANCE and t1 <= CONTACT_DISTANCE and t2 >= -CONTACT_DISTANCE
    return t1, t2, px, py, pz, h2, h, hit


@njit(cache=True, inline='always')
def _unit(a, b, s):
    """Length of segment s (a[s] -> b[s]) and its direction (zero for a zero length)."""
    dx = b[s, 0] - a[s, 0]
    dy = b[s, 1] - a[s, 1]
    dz = b[s, 2] - a[s, 2]
    ln = math.sqrt(dx * dx + dy * dy + dz * dz)
    if ln == 0:
        return 0.0, 0.0, 0.0, 0.0
    return ln, dx / ln, dy / ln, dz / ln


@njit(cache=True, inline='always')
def _pair_integral(a, b, s, positions, i, c2, c3):
    """Integral of ds / d^4 along segment s (a[s] -> b[s]) from threat i; inf on a hit."""
    ln, ux, uy, uz = _unit(a, b, s)
    if ln == 0:
        return 0.0
    return _along(a[s, 0], a[s, 1], a[s, 2], ux, uy, uz, ln, positions, i, c2, c3)


@njit(cache=True, inline='always')
def _along(ax, ay, az, ux, uy, uz, ln, positions, i, c2, c3):
    """Integral of ds / d^4 from threat i along ln [m] from (ax, ay, az) in direction u."""
    t1, t2, _, _, _, h2, h, hit = _foot(ax, ay, az, ux, uy, uz, ln, positions, i)
    if hit:
        return math.inf
    reach = _DIRECT_REACH * h
    if abs(t1) <= reach and abs(t2) <= reach:
        return _direct(t1, t2, h, h2, ln, 1.0 / (t1 * t1 + h2), 1.0 / (t2 * t2 + h2))[0]
    return _far(t1, t2, h, c2, c3)[0]


@njit(cache=True, inline='always')
def _segment_total(a, b, s, positions, f, c2, c3):
    """J_R of segment s over every threat (its direction computed once)."""
    ln, ux, uy, uz = _unit(a, b, s)
    if ln == 0:
        return 0.0
    ax, ay, az = a[s, 0], a[s, 1], a[s, 2]
    total = 0.0
    for i in range(positions.shape[0]):
        total += f[i] * _along(ax, ay, az, ux, uy, uz, ln, positions, i, c2, c3)
    return total
