"""Independent references of the detection model's tests.

The issue's equations, written without the module's code: P_d, the body frame, sigma,
SNR and H by scipy's quad.
"""

import math

import numpy as np
from scipy import integrate, special, stats

from threat_planner.core.detection.model import DetectionModel

UP = np.array([0.0, 0.0, 1.0])
P_FA = 1.0e-6
ELLIPSOID = (3.0, 1.0, 0.5)

# --------------------------------------------------------------------------- references


def ref_pd(snr_value, p_fa, swerling):
    """P_d per scan from the issue's formulas (scalar)."""
    x = -2.0 * math.log(p_fa)
    if swerling == 1:
        return p_fa ** (1.0 / (1.0 + snr_value))
    return float(stats.ncx2.sf(x, 2, 2.0 * snr_value))


def marcum_q1(a, b):
    """Q_1(a, b) by quadrature of the Rician density: int_b^inf x e^(-(x^2+a^2)/2) I_0(ax)."""
    def density(x):
        # e^(-(x^2 + a^2)/2) I_0(a x) = e^(-(x - a)^2 / 2) ive(0, a x)
        return x * math.exp(-0.5 * (x - a) ** 2) * special.ive(0, a * x)
    top = max(a, b) + 40.0
    if b < a:
        # Q_1 near 1: 1 - integral from 0 to b, done on the short side.
        below, _ = integrate.quad(density, 0.0, b, epsabs=0, epsrel=1e-13, limit=200)
        return 1.0 - below
    value, _ = integrate.quad(density, b, top, epsabs=0, epsrel=1e-13, limit=200)
    return value


def body_frame(e):
    """Rows: nose, right wing (horizontal), down, for a non-vertical direction e."""
    n = np.asarray(e, float) / np.linalg.norm(e)
    r = np.cross(n, UP)
    r /= np.linalg.norm(r)
    d = np.cross(n, r)
    return np.array([n, r, d])


def ref_sigma(e, p, q, model):
    """The issue's sigma: the ellipsoid seen along the unit line of sight in the body frame."""
    if model.rcs_kind == 'constant':
        return model.rcs_values[0]
    a, b, c = model.rcs_values
    g = np.asarray(q, float) - np.asarray(p, float)
    u = body_frame(e) @ (g / np.linalg.norm(g))
    return math.pi * (a * b * c) ** 2 / (a * a * u[0] ** 2 + b * b * u[1] ** 2
                                         + c * c * u[2] ** 2) ** 2


def ref_snr(e, p, q, f, model):
    g = np.asarray(q, float) - np.asarray(p, float)
    return f * ref_sigma(e, p, q, model) / np.dot(g, g) ** 2


def ref_pd_at(e, p, q, f, model):
    g = np.asarray(q, float) - np.asarray(p, float)
    if not np.any(g):
        return 1.0
    return ref_pd(ref_snr(e, p, q, f, model), model.p_fa, model.swerling)


def ref_hazard(points, positions, intensities, model, pieces=None):
    """Each threat's H_i by scipy quad per threat per segment (floor P_fa l exact)."""
    points = np.asarray(points, float)
    per = np.zeros(len(positions))
    todo = []
    if pieces is None:
        for k in range(len(points) - 1):
            for i in range(len(positions)):
                todo.append((k, i, 0.0, 1.0))
    else:
        todo = list(zip(*pieces))
    for k, i, f0, f1 in todo:
        a, b = points[k], points[k + 1]
        e = b - a
        length = np.linalg.norm(e)
        if length == 0 or f1 <= f0:
            continue
        q = positions[i]

        def excess(t):
            return ref_pd_at(e, a + t * e, q, intensities[i], model) - model.p_fa
        t_near = float(np.clip(np.dot(q - a, e) / np.dot(e, e), f0, f1))
        # Breaks at the closest approach and at 1/8 .. 2^20 radar ranges either side, so
        # each quad sees one smooth rise or fall (a long segment's steep Swerling 0 step
        # is otherwise a needle to quad).
        reach = (intensities[i] * model.largest_rcs) ** 0.25 / length
        offsets = reach * 2.0 ** np.arange(-3, 21)
        breaks = np.concatenate([[f0, t_near, f1], t_near - offsets, t_near + offsets])
        breaks = np.unique(np.clip(breaks, f0, f1))
        value = sum(integrate.quad(excess, lo, hi, epsabs=1e-20, epsrel=1e-11, limit=200)[0]
                    for lo, hi in zip(breaks[:-1], breaks[1:]))
        per[i] += (value + model.p_fa * (f1 - f0)) * length / model.metres_per_scan
    return per


def model(swerling=1, rcs='constant', values=(1.0,), **kw):
    return DetectionModel(p_fa=P_FA, swerling=swerling, rcs_kind=rcs, rcs_values=values,
                          **kw)


MODELS = [(s, kind, vals) for s in (0, 1)
          for kind, vals in (('constant', (2.0,)), ('ellipsoid', ELLIPSOID))]
MODEL_IDS = [f'swerling{s}-{k}' for s, k, _ in MODELS]

# A 3-D path through a field of strong radars (SNR 1..1e4 along it), non-level segments.
PATH = np.array([[0.0, 0.0, 10.0], [40.0, 10.0, 25.0], [80.0, -5.0, 20.0],
                 [120.0, 20.0, 20.0], [160.0, 0.0, 5.0]])
THREATS = np.array([[30.0, 25.0, 0.0], [75.0, -20.0, 10.0], [110.0, 35.0, 30.0],
                    [150.0, -10.0, 0.0], [60.0, 5.0, 60.0]])
F = np.array([3e7, 1e8, 5e6, 2e8, 4e7])
