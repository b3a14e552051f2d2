"""Threat model (paper Section 3.1) and the flight box."""

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from threat_planner.core.world.threats import as_point, Box, ThreatField
from threat_planner.errors import InputError


def test_received_power_follows_the_radar_equation():
    field = ThreatField.from_arrays([[0.0, 0, 0], [10.0, 0, 0]], [16.0, 32.0])
    # eq. 3: P = Q sum F_i / R_i^4; at x = 2: 16/16 + 32/4096.
    got = field.received_power([[2.0, 0, 0]], q=3.0)
    assert got == pytest.approx([3.0 * (1.0 + 32.0 / 8 ** 4)])
    assert np.isinf(field.received_power([[0.0, 0, 0]])[0])
    assert ThreatField.from_arrays(np.zeros((0, 3)), []).received_power([[1, 2, 3]]) == [0.0]


def test_near_pairs_cover_every_threat_within_the_radius():
    rng = np.random.default_rng(0)
    field = ThreatField.from_arrays(rng.uniform(0, 100, (300, 3)), np.ones(300))
    a, b = rng.uniform(0, 100, (20, 3)), rng.uniform(0, 100, (20, 3))
    seg, thr, bound = field.near_pairs(a, b, 15.0)
    found = set(zip(seg.tolist(), thr.tolist()))
    for s in range(20):
        # Distance from each threat to the segment, by dense sampling.
        pts = a[s] + np.linspace(0, 1, 2001)[:, None] * (b[s] - a[s])
        d = np.min(np.linalg.norm(pts[:, None] - field.positions[None], axis=2), axis=0)
        for i in np.flatnonzero(d < 15.0):
            assert (s, i) in found
    assert np.all(bound >= 0)


def test_box_and_point_validation():
    box = Box.from_corners([0, 0, 0], [1, 2, 3])
    assert box.contains(np.array([1.0, 2.0, 3.0])) and not box.contains(np.array([1.1, 0, 0]))
    assert np.allclose(box.clip(np.array([[5.0, -1.0, 1.0]])), [[1.0, 0.0, 1.0]])
    with pytest.raises(InputError, match='bounds: max.z'):
        Box.from_corners([0, 0, 3], [1, 2, 3])
    with pytest.raises(InputError, match='start: expected 3 coordinates'):
        as_point('start', [1.0, 2.0])
    with pytest.raises(InputError, match='threats: 2 positions but 1 intensities'):
        ThreatField.from_arrays([[0.0, 0, 0], [1, 1, 1]], [1.0])


def test_endpoint_check_finds_the_nearest_threat_without_a_tree():
    """The node's own process checks each start and goal it takes; a k-d tree there would
    import scipy.spatial (0.3 s) into a process that never plans. The nearest threat is
    the brute-force one, and a point within 1e-9 of the box diagonal of it is refused."""
    from threat_planner.core.world.threats import check_endpoints
    rng = np.random.default_rng(5)
    th = ThreatField.from_arrays(rng.uniform(0, 100, (50, 3)), np.ones(50))
    box = Box.from_corners([0, 0, 0], [100, 100, 100])
    s, t = check_endpoints([0, 0, 50], [100, 100, 50], box, th)
    assert s.tolist() == [0, 0, 50] and 'tree' not in vars(th)
    for k in (0, 17, 49):
        near = th.positions[k] + 1e-8   # 1.7e-8 from it: within 1.7e-7 of the box
        with pytest.raises(InputError, match=f'goal: .* is on threat {k}$'):
            check_endpoints([0, 0, 50], near, box, th)
    check_endpoints([0, 0, 50], th.positions[17] + 1e-6, box, th)  # 1.7e-6: not on it


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(1e-3, 1e9), min_size=1, max_size=40))
def test_median_intensity_is_numpy_s_median_bit_for_bit(values):
    """Computed without np.median, whose NaN check imports numpy.ma on a first plan."""
    n = len(values)
    field = ThreatField(np.zeros((n, 3)) + np.arange(n)[:, None], np.array(values))
    assert field.median_intensity == float(np.median(values))
