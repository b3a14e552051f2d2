"""The simulated vehicle: within its turn, climb and dive limits whatever it chases."""

import math

from hypothesis import assume, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from threat_planner.flight.vehicle import PointMass, ReferencePath

#: Slack on an angle [rad] or a relative radius: the float rounding of a step.
EPS = 1e-9
#: Largest turn of one step drawn [rad]: 20 m/s x 0.05 s on 10 m (fly's defaults).
MOST_PER_STEP = 0.1
#: Steepest climb and dive limits drawn [deg] (the defaults are 30).
STEEPEST = 45.0


def _heading(yaw_deg, pitch_deg):
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    return np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), math.sin(p)])


def _circumradius(a, b, c):
    """Radius of the circle through three points (inf on a line)."""
    ab, bc, ca = np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c)
    area2 = np.linalg.norm(np.cross(b - a, c - a))    # twice the triangle's area
    return math.inf if area2 <= 1e-12 * ab * bc else ab * bc * ca / (2.0 * area2)


def _fly(vehicle, targets, dt):
    """Step `vehicle` towards each (target, steps); return positions and headings."""
    pos, head = [vehicle.position.copy()], [vehicle.heading.copy()]
    for target, steps in targets:
        for _ in range(steps):
            vehicle.step(target, dt)
            pos.append(vehicle.position.copy())
            head.append(vehicle.heading.copy())
    return np.array(pos), np.array(head)


def _check_limits(pos, head, speed, dt, radius, climb, dive):
    """Assert the limits from the positions alone (and the headings), not the project's."""
    step = np.diff(pos, axis=0)
    assert np.allclose(np.linalg.norm(step, axis=1), speed * dt, rtol=1e-12)
    assert np.allclose(np.linalg.norm(head, axis=1), 1.0, rtol=1e-12)
    angle = np.degrees(np.arctan2(step[:, 2], np.hypot(step[:, 0], step[:, 1])))
    assert angle.max() <= climb + 1e-7 and -angle.min() <= dive + 1e-7
    if radius > 0:
        turn = np.arccos(np.clip(np.einsum('ij,ij->i', head[1:], head[:-1]), -1.0, 1.0))
        assert turn.max() <= speed * dt / radius + EPS
        radii = [_circumradius(*pos[k:k + 3]) for k in range(len(pos) - 2)]
        assert min(radii, default=math.inf) >= radius * (1 - 1e-7)


limits = st.fixed_dictionaries({
    'speed': st.floats(5.0, 60.0), 'dt': st.floats(0.01, 0.1),
    'radius': st.floats(1.0, 50.0), 'climb': st.floats(5.0, STEEPEST),
    'dive': st.floats(5.0, STEEPEST), 'yaw': st.floats(0.0, 360.0),
    'pitch_frac': st.floats(-1.0, 1.0)})
point = st.tuples(*[st.floats(-300.0, 300.0)] * 3)
targets = st.lists(st.tuples(point, st.integers(1, 60)), min_size=1, max_size=6)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(limits, targets)
def test_it_never_turns_tighter_nor_climbs_or_dives_steeper_than_its_limits(lim, goals):
    """Any targets; limits up to STEEPEST, a step turning at most MOST_PER_STEP.

    Steeper limits and coarser steps: the cases below (they broke the limits until the
    turn kept to the flight-path band).
    """
    assume(lim['speed'] * lim['dt'] / lim['radius'] <= MOST_PER_STEP)
    pitch = lim['pitch_frac'] * (lim['climb'] if lim['pitch_frac'] > 0 else lim['dive'])
    v = PointMass(np.array([0.0, 0.0, 100.0]), _heading(lim['yaw'], pitch), lim['speed'],
                  lim['radius'], lim['climb'], lim['dive'])
    pos, head = _fly(v, [(np.array(t, float), n) for t, n in goals], lim['dt'])
    _check_limits(pos, head, lim['speed'], lim['dt'], lim['radius'], lim['climb'],
                  lim['dive'])


@pytest.mark.parametrize('target', [[-100.0, 0.0, 100.0], [-100.0, 1e-9, 100.0],
                                    [0.0, 0.0, 400.0], [0.0, 0.0, -300.0], [1.0, 0.0, 100.0]])
def test_straight_behind_above_below_or_too_close_it_still_keeps_the_limits(target):
    v = PointMass(np.array([0.0, 0.0, 100.0]), np.array([1.0, 0.0, 0.0]), 20.0, 10.0, 30.0,
                  25.0)
    pos, head = _fly(v, [(np.array(target), 200)], 0.05)
    _check_limits(pos, head, 20.0, 0.05, 10.0, 30.0, 25.0)


def test_behind_it_comes_round_and_reaches_the_target():
    v = PointMass(np.array([0.0, 0.0, 50.0]), np.array([1.0, 0.0, 0.0]), 20.0, 10.0, 30.0,
                  30.0)
    target = np.array([-80.0, 0.0, 50.0])
    pos, _ = _fly(v, [(target, 300)], 0.05)
    assert np.linalg.norm(pos - target, axis=1).min() < 20.0 * 0.05


@pytest.mark.parametrize('yaw, pitch', [(0.0, 0.0), (37.0, 12.0), (200.0, -29.0)])
def test_a_straight_line_is_followed_exactly(yaw, pitch):
    h = _heading(yaw, pitch)
    start = np.array([10.0, -20.0, 60.0])
    line = ReferencePath([start, start + 400.0 * h])
    v = PointMass(start.copy(), h.copy(), 20.0, 10.0, 30.0, 30.0)
    s = 0.0
    for k in range(1, 301):
        v.step(line.ahead(s + 10.0), 0.05)    # pure pursuit, 10 m ahead, as fly does
        s = line.project(v.position, 0.0, line.length)
        assert np.linalg.norm(v.position - (start + k * 1.0 * h)) < 1e-9
        assert np.linalg.norm(v.heading - h) < 1e-12
    assert s == pytest.approx(300.0, abs=1e-9)


def test_without_limits_it_flies_straight_at_the_target():
    v = PointMass(np.zeros(3), np.array([1.0, 0.0, 0.0]), 10.0)
    v.step(np.array([0.0, 0.0, -50.0]), 0.1)
    assert v.position == pytest.approx([0.0, 0.0, -1.0])


def test_a_turn_at_a_steep_climb_limit_keeps_the_turn_radius():
    v = PointMass(np.zeros(3), _heading(0.0, 80.0), 20.0, 10.0, 80.0, 80.0)
    pos, head = _fly(v, [(1000.0 * _heading(122.0, 20.0), 3)], 0.05)
    _check_limits(pos, head, 20.0, 0.05, 10.0, 80.0, 80.0)


@pytest.mark.parametrize('target', [[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
def test_a_step_that_turns_past_the_vertical_keeps_the_limits(target):
    """A coarse step (26 m/s x 0.0625 s on a 1 m radius: 93 deg) at a target below."""
    v = PointMass(np.array([0.0, 0.0, 100.0]), np.array([1.0, 0.0, 0.0]), 26.0, 1.0, 5.0,
                  5.0)
    pos, head = _fly(v, [(np.array(target), 1)], 0.0625)
    _check_limits(pos, head, 26.0, 0.0625, 1.0, 5.0, 5.0)


def test_without_a_turn_limit_a_target_straight_below_keeps_the_speed():
    """No turn limit, a dive limit: the clamp must still give a unit heading."""
    v = PointMass(np.array([0.0, 0.0, 100.0]), np.array([1.0, 0.0, 0.0]), 20.0, 0.0, 30.0,
                  30.0)
    pos, head = _fly(v, [(np.array([0.0, 0.0, 0.0]), 5)], 0.05)
    _check_limits(pos, head, 20.0, 0.05, 0.0, 30.0, 30.0)
