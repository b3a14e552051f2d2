"""Mass-spring potential-field smoothing (paper Section 3.4, eq. 4-14) and angle checks."""

import numpy as np
import pytest

from threat_planner.core.optimise.smoothing import (chain_forces, check_angles, pitch_angles,
                                                    resample, smooth, turn_angles)


def test_resample_gives_equal_steps_and_keeps_the_ends():
    poly = np.array([[0.0, 0, 0], [10, 0, 0], [10, 10, 0]])
    pts = resample(poly, 8)
    assert len(pts) == 9
    assert np.allclose(pts[0], poly[0]) and np.allclose(pts[-1], poly[-1])
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert steps[:4] == pytest.approx(np.full(4, 2.5))


def test_pitch_and_turn_angles_of_known_paths():
    pts = np.array([[0.0, 0, 0], [1, 0, 1], [2, 0, 1], [2, 1, 1]])
    assert pitch_angles(pts) == pytest.approx([45.0, 0.0, 0.0])
    assert turn_angles(pts) == pytest.approx([45.0, 90.0])
    check = check_angles(pts, max_pitch_deg=40, max_turn_deg=100)
    assert not check.pitch_ok and check.turn_ok and not check.feasible


def test_repulsion_follows_eq_13_and_springs_only_pull():
    x = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    v = np.zeros_like(x)
    threat, f = np.array([[1.0, 2.0, 0.0]]), np.array([32.0])
    force = chain_forces(x, v, threat, f, k=0.0, b=0.0, q=0.5, rest_length=0.0)
    # Q F / d^4 = 0.5 * 32 / 16 = 1, pointing from the threat to the mass.
    assert force[1] == pytest.approx([0.0, -1.0, 0.0])
    # Rest length longer than the springs: a rubber band goes slack, it never pushes.
    slack = chain_forces(x, v, np.zeros((0, 3)), np.zeros(0), k=10.0, b=0.0, q=0.0,
                         rest_length=2.0)
    assert np.allclose(slack, 0.0)
    taut = chain_forces(x, v, np.zeros((0, 3)), np.zeros(0), k=10.0, b=0.0, q=0.0,
                        rest_length=0.5)
    assert taut[0] == pytest.approx([5.0, 0, 0]) and taut[2] == pytest.approx([-5.0, 0, 0])


def test_damping_acts_on_relative_velocity_along_the_spring():
    x = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    v = np.array([[0.0, 0, 0], [2.0, 3.0, 0]])
    f = chain_forces(x, v, np.zeros((0, 3)), np.zeros(0), k=0.0, b=4.0, q=0.0, rest_length=0.0)
    assert f[1] == pytest.approx([-8.0, 0.0, 0.0])   # eq. 9-10: only the along-spring part


def test_chain_without_threats_relaxes_to_the_straight_line():
    bent = resample(np.array([[0.0, 0, 0], [50, 40, 10], [100, 0, 0]]), 20)
    r = smooth(bent, np.zeros((0, 3)), np.zeros(0), k=1000, damping=20, mass=1, q=500)
    assert r.converged and 0 < r.steps < 4000
    assert np.max(np.abs(r.points[:, 1:])) < 1e-2


def test_threat_pushes_the_chain_away():
    line = resample(np.array([[0.0, 0, 0], [100, 0, 0]]), 20)
    threat, f = np.array([[50.0, 3.0, 0.0]]), np.array([2e5])
    r = smooth(line, threat, f, k=1000, damping=20, mass=1, q=500)
    before = np.min(np.linalg.norm(line - threat, axis=1))
    after = np.min(np.linalg.norm(r.points - threat, axis=1))
    assert r.converged
    assert after > before + 1.0
    assert np.allclose(r.points[[0, -1]], line[[0, -1]])
    # Stiffer springs straighten the chain: less deflection at larger k.
    stiff = smooth(line, threat, f, k=3000, damping=20, mass=1, q=500)
    assert np.min(np.linalg.norm(stiff.points - threat, axis=1)) < after


def _reference_smooth(points, positions, intensities, k, damping, mass, q, steps, bounds):
    """The integration as it ran in numpy before it was compiled: ``steps`` steps, no stop."""
    x = np.array(points, float)
    v = np.zeros_like(x)
    n = len(x) - 1
    dt = 0.5 * np.sqrt(mass / k)
    drag = 2.0 * mass * 2.0 * np.sqrt(k / mass) * np.sin(np.pi / (2 * n))
    spacing = max(float(np.linalg.norm(x[-1] - x[0])) / n,
                  float(np.linalg.norm(np.diff(x, axis=0), axis=1).mean()), 1e-9)
    for _ in range(steps):
        f = chain_forces(x, v, positions, intensities, k, damping, q, 0.0) - drag * v
        v[1:-1] += dt * f[1:-1] / mass
        move = dt * v
        size = np.linalg.norm(move, axis=1)
        big = size > 0.25 * spacing
        move[big] *= (0.25 * spacing / size[big])[:, None]
        v[big] = move[big] / dt
        x[1:-1] += move[1:-1]
        if bounds is not None:
            clipped = np.clip(x, bounds[0], bounds[1])
            v[clipped != x] = 0.0
            x = clipped
    return x


@pytest.mark.parametrize('walls', [False, True])
def test_compiled_forces_and_steps_are_the_numpy_chain(walls):
    # The compiled integration (chain_kernels) against chain_forces and the numpy step:
    # the same to rounding (numpy's power and einsum round some results differently).
    from threat_planner.core.optimise.chain_kernels import _forces
    rng = np.random.default_rng(4)
    for trial in range(20):
        n, m = int(rng.integers(4, 30)), int(rng.integers(0, 25))
        x = rng.uniform(0, 100, (n + 1, 3))
        v = rng.normal(0, 2, (n + 1, 3))
        pos, f = rng.uniform(0, 100, (m, 3)), rng.uniform(1e3, 1e5, m)
        if m:
            pos[0] = x[2]                     # a mass on a threat feels no push from it
        got = np.empty_like(x)
        _forces(x, v, pos.reshape(-1, 3), f, 2.0, 0.7, 1.5, 0.3, got)
        ref = chain_forces(x, v, pos, f, 2.0, 0.7, 1.5, 0.3)
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
        # 200 steps either way (max_steps, tolerance 0: the stopping rule never fires).
        chain = np.linspace([0.0, 0.0, 50.0], [100.0, 100.0, 50.0], n + 1)
        chain[1:-1] += rng.normal(0, 4, (n - 1, 3))
        bounds = (np.zeros(3), np.full(3, 100.0)) if walls else None
        r = smooth(chain, pos, f, k=3.0, damping=1.0, mass=1.0, q=1.0, max_steps=200,
                   tolerance=0.0, bounds=bounds)
        assert r.steps == 200 and not r.converged
        ref = _reference_smooth(chain, pos, f, 3.0, 1.0, 1.0, 1.0, 200, bounds)
        np.testing.assert_allclose(r.points, ref, rtol=0, atol=1e-7)
        assert np.array_equal(r.points[[0, -1]], chain[[0, -1]])
