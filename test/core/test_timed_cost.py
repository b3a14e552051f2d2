"""The J of a path in time: exact against quadrature, the static J when nothing moves."""

import numpy as np
import pytest

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.flight.timed_cost import (closest_approach, timed_path_cost,
                                                   timed_segment_costs)
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError


def _field(rng, n=6):
    return ThreatField.from_arrays(rng.uniform(0, 100, (n, 3)), rng.uniform(1e5, 4e5, n))


def _path(rng, m=6):
    pts = np.vstack([[0, 0, 50], rng.uniform(10, 90, (m - 2, 3)), [100, 100, 50]])
    length = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    return pts, length


def _quadrature(pts, times, timeline, n=200_000):
    """Midpoint rule over arc length, every piece at its position at each sample's time."""
    ids, f, origin, vel, on, off, _ = timeline.pieces()
    length = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    s = (np.arange(n) + 0.5) * length[-1] / n
    p = np.stack([np.interp(s, length, pts[:, k]) for k in range(3)], axis=1)
    t = np.interp(s, length, times)
    total = 0.0
    for k in range(len(f)):
        live = (t >= on[k]) & (t < off[k])
        q = origin[k] + vel[k] * (t - on[k])[:, None]
        total += f[k] * np.sum(live / np.sum((p - q) ** 2, axis=1) ** 2) * length[-1] / n
    return total


def test_still_threats_present_throughout_cost_the_static_j():
    rng = np.random.default_rng(3)
    field = _field(rng)
    pts, length = _path(rng)
    for speed in (5.0, 20.0, 300.0):
        timed = timed_path_cost(pts, length / speed, ThreatTimeline(field), 0.4)
        static = path_cost(pts, field.positions, field.intensities, 0.4)
        assert timed.J_L == static.J_L
        assert timed.J_R == pytest.approx(static.J_R, rel=1e-12)


@pytest.mark.parametrize('seed', range(5))
def test_moving_popping_and_leaving_threats_match_quadrature(seed):
    rng = np.random.default_rng(seed)
    field = _field(rng)
    pts, length = _path(rng)
    speed = rng.uniform(10, 30)
    times = length / speed
    tl = ThreatTimeline(field, rng.uniform(-30, 30, (len(field), 3)))
    tl.add(times[-1] * 0.3, rng.uniform(20, 80, 3), 2e5, rng.uniform(-10, 10, 3))
    tl.move(times[-1] * 0.5, 0, velocity=rng.uniform(-20, 20, 3))
    tl.move(times[-1] * 0.6, 1, position=rng.uniform(0, 100, 3))
    tl.remove(times[-1] * 0.7, 2)
    exact = timed_path_cost(pts, times, tl, 0.5).J_R
    assert exact == pytest.approx(_quadrature(pts, times, tl), rel=1e-6)


def test_a_threat_keeping_pace_costs_its_constant_distance():
    """g = 0: the relative position is still; the integral is L / d^4."""
    field = ThreatField.from_arrays([[0.0, 10.0, 0.0]], [1e5])
    tl = ThreatTimeline(field, [[20.0, 0.0, 0.0]])
    pts = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
    cost = timed_path_cost(pts, [0.0, 5.0], tl, 0.5)
    assert cost.J_R == pytest.approx(1e5 * 100.0 / 10.0 ** 4, rel=1e-12)


def test_a_threat_active_only_after_the_flight_costs_nothing():
    rng = np.random.default_rng(1)
    tl = ThreatTimeline(ThreatField.from_arrays(np.zeros((0, 3)), np.zeros(0)))
    tl.add(100.0, [50, 50, 50], 1e6)
    pts, length = _path(rng)
    assert timed_path_cost(pts, length / 20, tl, 0.5).J_R == 0.0
    assert np.all(timed_segment_costs(pts, length / 20, tl) == 0.0)


def test_hovering_and_segment_splits_are_consistent():
    """J_R is over arc length: a pause costs nothing, splitting a segment changes nothing."""
    rng = np.random.default_rng(2)
    tl = ThreatTimeline(_field(rng), rng.uniform(-10, 10, (6, 3)))
    a, b = np.array([0.0, 0, 50]), np.array([100.0, 100, 50])
    whole = timed_path_cost([a, b], [0.0, 7.0], tl, 0.5).J_R
    mid = 0.5 * (a + b)
    split = timed_path_cost([a, mid, b], [0.0, 3.5, 7.0], tl, 0.5).J_R
    paused = timed_path_cost([a, a, b], [0.0, 0.0, 7.0], tl, 0.5).J_R
    assert split == pytest.approx(whole, rel=1e-12)
    assert paused == pytest.approx(whole, rel=1e-12)


def test_closest_approach_matches_dense_sampling():
    rng = np.random.default_rng(4)
    tl = ThreatTimeline(_field(rng), rng.uniform(-20, 20, (6, 3)))
    pts, length = _path(rng)
    times = length / 15
    dist, when = closest_approach(pts, times, tl)
    ids, f, origin, vel, on, off, _ = tl.pieces()
    s = np.linspace(0, length[-1], 400_001)
    p = np.stack([np.interp(s, length, pts[:, k]) for k in range(3)], axis=1)
    t = np.interp(s, length, times)
    for k in range(len(f)):
        d = np.linalg.norm(p - (origin[k] + vel[k] * (t - on[k])[:, None]), axis=1)
        assert dist[k] == pytest.approx(d.min(), abs=1e-3)
        assert when[k] == pytest.approx(t[np.argmin(d)], abs=1e-3)


def test_bad_times_are_refused():
    tl = ThreatTimeline(ThreatField.from_arrays([[1.0, 1, 1]], [1.0]))
    with pytest.raises(InputError, match='times: 1 times for 2 points'):
        timed_path_cost([[0, 0, 0], [1, 0, 0]], [0.0], tl, 0.5)
    with pytest.raises(InputError, match='non-decreasing'):
        timed_path_cost([[0, 0, 0], [1, 0, 0]], [1.0, 0.0], tl, 0.5)
    with pytest.raises(InputError, match='non-decreasing'):
        timed_path_cost([[0, 0, 0], [1, 0, 0]], [0.0, np.nan], tl, 0.5)


def test_timeline_pieces_and_snapshots():
    field = ThreatField.from_arrays([[0.0, 0, 0], [10.0, 0, 0]], [1.0, 2.0])
    tl = ThreatTimeline(field, [[1.0, 0, 0], [0, 0, 0]], lethal=[np.nan, 3.0])
    assert not ThreatTimeline(field).moving() and tl.moving()
    new = tl.add(2.0, [5.0, 5, 5], 7.0, lethal_radius=1.0)
    assert new == 2
    tl.move(4.0, 0, velocity=[0.0, 2, 0])
    tl.remove(5.0, 1)
    snap = tl.snapshot(6.0)
    assert sorted(snap.ids.tolist()) == [0, 2]
    at = dict(zip(snap.ids.tolist(), snap.field.positions.tolist()))
    assert at[0] == pytest.approx([4.0, 4.0, 0.0])    # 4 m along x, then 2 s at 2 m/s
    assert at[2] == [5.0, 5.0, 5.0]
    assert tl.snapshot(1.0).ids.tolist() == [0, 1]
    with pytest.raises(InputError, match='remove_threat.index: threat 1 was removed'):
        tl.remove(6.0, 1)
    with pytest.raises(InputError, match='move_threat.index: threat 9 does not exist'):
        tl.move(6.0, 9, velocity=[0, 0, 0])
    with pytest.raises(InputError, match='threats.velocity'):
        ThreatTimeline(field, [[np.nan, 0, 0], [0, 0, 0]])
