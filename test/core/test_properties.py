"""Property-based tests (hypothesis): the library's contracts on random and degenerate input.

Every plan() call either returns a plan that starts at the start, ends at the goal, stays in
the box and reports the J that path_cost gives it, or raises one of the project's own errors
(ThreatPlannerError) with a one-line message; never another exception and never a hang.
"""

import math

from hypothesis import assume, example, given, strategies as st
from hypothesis.extra.numpy import arrays
import numpy as np
import pytest

from property_harness import (_guarded, _note, CHEAP, fractions, PLANS, scales, time_limit,
                              unit_points)
from threat_planner.core.cost.closed_form import CONTACT_DISTANCE, path_cost, segment_threat_costs
from threat_planner.core.network.partition import build_network
from threat_planner.core.planner import plan, PlannerConfig
from threat_planner.core.world.threats import Box, ThreatField


# ---------------------------------------------------------------------------- strategies


@st.composite
def boxes(draw):
    """A valid box, sides 1e-6..1e7: at the origin, offset by its size, or up to 1e7 away."""
    scale = draw(scales)
    size = scale * np.array(draw(st.lists(st.floats(1.0, 10.0), min_size=3, max_size=3)))
    where = draw(st.sampled_from(['origin', 'near', 'far']))
    if where == 'origin':
        lo = np.zeros(3)
    elif where == 'near':
        lo = scale * np.array(draw(st.lists(st.floats(-10, 10), min_size=3, max_size=3)))
    else:
        lo = np.array(draw(st.lists(st.floats(-1e7, 1e7), min_size=3, max_size=3)))
    return lo, lo + size


def _in_box(lo, hi, frac):
    return lo + np.asarray(frac) * (hi - lo)


@st.composite
def threat_positions(draw, lo, hi):
    """0-6 threats: random, duplicated, 1e-9 apart, collinear, coplanar or outside."""
    kind = draw(st.sampled_from(['random', 'duplicate', 'near_duplicate', 'collinear',
                                 'coplanar', 'ground', 'outside']))
    if kind == 'random':
        n = draw(st.integers(0, 3))
        pts = [_in_box(lo, hi, draw(unit_points)) for _ in range(n)]
    elif kind in ('duplicate', 'near_duplicate'):
        p = _in_box(lo, hi, draw(unit_points))
        n = draw(st.integers(2, 4))
        step = 0.0 if kind == 'duplicate' else 1e-9
        direction = np.array([1.0, 0.5, 0.25])
        pts = [p + i * step * direction for i in range(n)]
    elif kind == 'collinear':
        a, b = (_in_box(lo, hi, draw(unit_points)) for _ in range(2))
        ts = draw(st.lists(fractions, min_size=2, max_size=6))
        pts = [a + t * (b - a) for t in ts]
    elif kind == 'coplanar':
        a, b, c = (_in_box(lo, hi, draw(unit_points)) for _ in range(3))
        uv = draw(st.lists(st.tuples(fractions, fractions), min_size=3, max_size=6))
        pts = [a + u * (b - a) + v * (c - a) for u, v in uv]
    elif kind == 'ground':
        z = draw(st.sampled_from([0.0, 0.5, 1.0]))
        xy = draw(st.lists(st.tuples(fractions, fractions), min_size=1, max_size=6))
        pts = [_in_box(lo, hi, [x, y, z]) for x, y in xy]
    else:
        n = draw(st.integers(1, 3))
        pts = [_in_box(lo, hi, draw(arrays(float, 3, elements=st.floats(-2.0, 3.0))))
               for _ in range(n)]
    return np.array(pts, float).reshape(-1, 3)


@st.composite
def intensities(draw, n):
    """Valid intensities F > 0: ordinary (1e-6..1e6) and occasionally extreme."""
    ordinary = st.floats(-6.0, 6.0).map(lambda e: 10.0 ** e)
    extreme = st.sampled_from([1e-300, 5e-324, 1e30, 1e300, 1.7e308])
    value = st.one_of(*[ordinary] * 9, extreme)
    return np.array(draw(st.lists(value, min_size=n, max_size=n)), float)


@st.composite
def endpoint(draw, lo, hi):
    """A valid start or goal: anywhere in the box, often on its faces or corners."""
    frac = draw(arrays(float, 3, elements=fractions | st.sampled_from([0.0, 1.0])))
    return _in_box(lo, hi, frac)


@st.composite
def planning_problems(draw):
    """(threat positions, intensities, start, goal, box corners, w), sometimes corrupted.

    About one problem in four has one defect: a bad intensity (0, negative, NaN, inf), an
    endpoint on a threat, outside the box or not finite, or a box with a flat side.
    """
    lo, hi = draw(boxes())
    pos = draw(threat_positions(lo, hi))
    f = draw(intensities(len(pos)))
    start = draw(endpoint(lo, hi))
    goal = start.copy() if draw(st.integers(0, 7)) == 0 else draw(endpoint(lo, hi))
    w = draw(st.sampled_from([0.05, 0.5, 0.95]))
    defects = ['none'] * 9 + ['intensity', 'on_threat', 'outside', 'not_finite', 'flat_box']
    defect = draw(st.sampled_from(defects))
    for p in (start, goal):
        # Simple draws often put an endpoint exactly on a threat; keep that for 'on_threat'.
        if len(pos) and np.linalg.norm(pos - p, axis=1).min() <= 1e-6 * np.linalg.norm(hi - lo):
            p += 1e-3 * (0.5 * (lo + hi) - p)
    which = draw(st.sampled_from([start, goal]))
    if defect == 'intensity' and len(pos):
        f[draw(st.integers(0, len(f) - 1))] = draw(
            st.sampled_from([0.0, -0.0, -1.0, -1e-300, math.nan, math.inf, -math.inf]))
    elif defect == 'on_threat' and len(pos):
        which[:] = pos[draw(st.integers(0, len(pos) - 1))]
    elif defect == 'outside':
        which[draw(st.integers(0, 2))] = draw(st.sampled_from([
            lo[0] - (hi[0] - lo[0]), hi[2] + 1e-3 * (hi[2] - lo[2])]))
    elif defect == 'not_finite':
        which[draw(st.integers(0, 2))] = draw(st.sampled_from([math.nan, math.inf]))
    elif defect == 'flat_box':
        hi = hi.copy()
        hi[draw(st.integers(0, 2))] = lo[0]
    return pos, f, start, goal, (lo, hi), w


def _run_plan(problem, method):
    pos, f, start, goal, (lo, hi), w = problem
    config = PlannerConfig(w=w, method=method, n_points=12, routes=2)

    def pipeline():
        field = ThreatField.from_arrays(pos, f)
        box = Box.from_corners(lo, hi)
        return field, box, plan(field, start, goal, box, config)

    out = _guarded(pipeline)
    if out is None:
        return
    field, box, result = out
    _note('planned')
    path = result.path
    assert np.array_equal(path[0], start), (path[0], start)
    assert np.array_equal(path[-1], goal), (path[-1], goal)
    # The tolerance with which Box.contains accepts the start and goal.
    tol = 1e-9 * max(box.diagonal, 1.0)
    assert np.all(path >= box.lo - tol) and np.all(path <= box.hi + tol)
    again = path_cost(path, field.positions, field.intensities, w)
    assert np.isfinite(result.cost.J), result.cost
    assert result.cost.J == pytest.approx(again.J, rel=1e-9)


def _problem(pos, f, start, goal, lo, hi, w=0.5):
    arr = np.asarray
    return (arr(pos, float).reshape(-1, 3), arr(f, float), start, goal,
            (arr(lo, float), arr(hi, float)), w)


#: Hand-picked problems (each one once found a bug), run for every method.
KNOWN_PROBLEMS = {
    'start_equals_goal_on_a_corner': _problem(
        [[0, 0, 0.0625], [0, 0, 0.0625]], [1, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0],
        [1, 1, 0.25]),
    'box_1e-7_wide_at_1e7': _problem(
        [], [], [1e7] * 3, [1e7 + 1e-7] * 3, [1e7] * 3, [1e7 + 1e-7] * 3),
    'box_1e-6_wide_at_1e7': _problem(
        [], [], [1e7] * 3, [1e7 + 1e-6] * 3, [1e7] * 3, [1e7 + 1e-6] * 3),
    'box_1e-6_wide_at_1e7_with_threats': _problem(
        [[1e7 + 5e-7, 1e7 + 5e-7, 1e7 + 1e-7], [1e7 + 5e-7, 1e7 + 5e-7, 1e7 + 1e-7]],
        [1, 1], [1e7] * 3, [1e7 + 1e-6] * 3, [1e7] * 3, [1e7 + 1e-6] * 3),
    # |goal - start|^2 underflows: resample() returned copies of the start (fixed).
    'goal_1e-200_from_start': _problem([], [], [0, 0, 0], [0, 1e-200, 0], [0, 0, 0], [1, 1, 1]),
    'huge_intensity': _problem(
        [[0.5, 0.5, 0.5]], [1e306], [0, 0, 0], [1, 1, 1], [0, 0, 0], [1, 1, 1]),
    'start_beyond_float_range': _problem(
        [[0.5, 0.5, 0.5]], [1], [10 ** 400, 0, 0], [1, 1, 1], [0, 0, 0], [1, 1, 1]),
    # Threats on two box corners, start and goal near one: the paper's chain leaves the
    # box and box.clip() puts its vertices on the corner threat (J = inf).
    'chain_clipped_onto_a_corner_threat': _problem(
        [[0, 0, 0], [1, 1, 1]], [1, 1], [0.01] * 3, [0.02] * 3, [0, 0, 0], [1, 1, 1]),
}


@pytest.mark.parametrize('method', ['paper', 'best'])
@pytest.mark.parametrize('name', sorted(KNOWN_PROBLEMS))
def test_plan_on_known_problems(name, method):
    _run_plan(KNOWN_PROBLEMS[name], method)


@PLANS
@given(planning_problems())
def test_plan_paper_returns_a_valid_plan_or_a_project_error(problem):
    _run_plan(problem, 'paper')


@PLANS
@given(planning_problems())
def test_plan_best_returns_a_valid_plan_or_a_project_error(problem):
    _run_plan(problem, 'best')


# ---------------------------------------------------------------------------- path_cost

def _point_segment_distance(p, a, b):
    d = b - a
    L2 = float(d @ d)
    t = 0.0 if L2 == 0 else min(max(float((p - a) @ d) / L2, 0.0), 1.0)
    return float(np.linalg.norm(a + t * d - p))


@st.composite
def cost_cases(draw, min_clearance=0.0):
    """A polyline and threats that keep a fraction of the scene's scale clear of it."""
    scale = draw(scales)
    n = draw(st.integers(2, 6))
    path = scale * draw(arrays(float, (n, 3), elements=st.floats(-1.0, 1.0)))
    m = draw(st.integers(0, 4))
    pos = scale * draw(arrays(float, (m, 3), elements=st.floats(-1.5, 1.5)))
    if m and draw(st.booleans()):
        # A threat on the line of a segment, beyond its end: the cancellation-prone case.
        i = draw(st.integers(0, n - 2))
        t = draw(st.sampled_from([-1.0, -0.01, 1.01, 2.0, 10.0]))
        pos[0] = path[i] + t * (path[i + 1] - path[i])
    f = draw(st.floats(-6.0, 6.0).map(lambda e: 10.0 ** e)
             .flatmap(lambda c: arrays(float, m, elements=st.floats(0.1, 10.0)).map(
                 lambda a: c * a)))
    clearance = max(2 * CONTACT_DISTANCE, min_clearance * scale)
    for p in pos:
        for a, b in zip(path[:-1], path[1:]):
            assume(_point_segment_distance(p, a, b) > clearance)
    w = draw(st.floats(0.01, 0.99))
    return path, pos, f, w, scale


@CHEAP
@given(cost_cases())
def test_path_cost_is_finite_and_at_least_the_weighted_straight_line(case):
    path, pos, f, w, _ = case
    c = path_cost(path, pos, f, w)
    assert np.isfinite(c.J) and np.isfinite(c.J_R) and np.isfinite(c.J_L)
    assert c.J_R >= 0.0
    straight = (1.0 - w) * float(np.linalg.norm(path[-1] - path[0]))
    assert c.J >= straight * (1.0 - 1e-12)


@CHEAP
@given(cost_cases(min_clearance=1e-3),
       arrays(float, 3, elements=st.floats(-100.0, 100.0)))
def test_path_cost_is_invariant_under_translation(case, shift):
    path, pos, f, w, scale = case
    v = scale * shift
    c0 = path_cost(path, pos, f, w)
    c1 = path_cost(path + v, pos + v, f, w)
    assert c1.J_L == pytest.approx(c0.J_L, rel=1e-9)
    assert c1.J_R == pytest.approx(c0.J_R, rel=1e-9)
    assert c1.J == pytest.approx(c0.J, rel=1e-9)


@CHEAP
@given(cost_cases(), st.floats(-6.0, 6.0).map(lambda e: 10.0 ** e))
def test_scaling_the_intensities_scales_the_threat_cost(case, c):
    path, pos, f, w, _ = case
    j_r = path_cost(path, pos, f, w).J_R
    assert path_cost(path, pos, c * f, w).J_R == pytest.approx(c * j_r, rel=1e-12)
    per_segment = segment_threat_costs(path[:-1], path[1:], pos, c * f)
    assert per_segment.sum() == pytest.approx(c * j_r, rel=1e-12)


# ---------------------------------------------------------------------------- build_network

@st.composite
def network_inputs(draw):
    """Any finite point set (incl. 0-3 points, flat, identical) and a box."""
    lo, hi = draw(boxes())
    kind = draw(st.sampled_from(['threats', 'identical', 'wild']))
    if kind == 'threats':
        pts = draw(threat_positions(lo, hi))
    elif kind == 'identical':
        p = _in_box(lo, hi, draw(unit_points))
        pts = np.repeat(p[None], draw(st.integers(1, 6)), axis=0)
    else:
        pts = draw(arrays(float, (draw(st.integers(0, 5)), 3),
                          elements=st.floats(-1e9, 1e9)))
    return pts, Box.from_corners(lo, hi), draw(st.integers(1, 3))


@CHEAP
# A threat 1e13 box diagonals away: Qhull gives up (QH6227), or leaks its point at infinity.
@example((np.array([[1.24434462e8, 0.0, 1.24434462e8]]),
          Box.from_corners([0, 0, 0], [1e-5, 2.5e-6, 1e-5]), 1))
@example((np.array([[1.30830341e8] * 3]), Box.from_corners([0, 0, 0], [1e-5, 5e-6, 5e-6]), 1))
# A box 1e-7 wide at 1e7 (54 ulps across): the lattice is flat to Qhull (QH6154).
@example((np.zeros((0, 3)), Box.from_corners([1e7] * 3, [1e7 + 1e-7] * 3), 2))
@given(network_inputs())
def test_build_network_never_raises_and_neighbours_share_a_face(case):
    pts, box, divisions = case
    with time_limit():
        net = build_network(pts, box, divisions)
    assert net.n_nodes >= 1
    assert np.all(np.isfinite(net.nodes))
    a, b = net.tetrahedra[net.edges[:, 0]], net.tetrahedra[net.edges[:, 1]]
    shared = (a[:, :, None] == b[:, None, :]).sum(axis=(1, 2))
    assert np.all(shared == 3), np.flatnonzero(shared != 3)
