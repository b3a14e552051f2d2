"""Plans in time: the static plan when nothing moves, the heading kept, exact costs."""

import math
from pathlib import Path

import numpy as np
import pytest

from threat_planner.core.flight.entry import enter, unit_heading
from threat_planner.core.flight.replan import plan_in_time
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.optimise.limits import check_limits, FlightLimits, turn_radii
from threat_planner.core.planner import plan
from threat_planner.core.world.threats import Box, ThreatField
from threat_planner.errors import InputError

DATA = Path(__file__).resolve().parents[1] / 'data'


@pytest.fixture(scope='module')
def scenario():
    return load_scenario(DATA / 'uniform20_0.yaml')


def test_still_threats_plan_as_the_planner_does(scenario):
    cfg = PlannerConfig()
    timed = plan_in_time(ThreatTimeline(scenario.threats), scenario.start, scenario.goal,
                         scenario.box, cfg, 20.0)
    static = plan(scenario.threats, scenario.start, scenario.goal, scenario.box, cfg)
    assert timed.rounds == 1
    assert np.array_equal(timed.points, static.path)
    assert timed.cost.J == pytest.approx(static.cost.J, rel=1e-12)
    length = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(static.path, axis=0),
                                                           axis=1))])
    assert np.allclose(timed.times, length / 20.0)


def _crossing():
    """A strong threat that crosses the straight line at the time the UAV passes."""
    box = Box.from_corners([0, 0, 0], [200, 200, 100])
    field = ThreatField.from_arrays([[100.0, 40.0, 50.0], [60.0, 150.0, 50.0]], [4e5, 1e5])
    return box, field, [[0.0, 12.0, 0.0], [0.0, 0.0, 0.0]]


def test_a_crossing_threat_is_met_where_it_will_be():
    box, field, vel = _crossing()
    tl = ThreatTimeline(field, vel)
    start, goal, speed = [0.0, 100.0, 50.0], [200.0, 100.0, 50.0], 20.0
    cfg = PlannerConfig()
    timed = plan_in_time(tl, start, goal, box, cfg, speed)
    naive = plan(field, start, goal, box, cfg).path    # threats frozen where they are now
    length = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(naive, axis=0), axis=1))])
    naive_j = timed_path_cost(naive, length / speed, tl, cfg.w).J
    assert timed.cost.J < 0.9 * naive_j
    # The reported cost is the exact timed J of the reported path and times.
    assert timed.cost.J == timed_path_cost(timed.points, timed.times, tl, cfg.w).J
    assert check_limits(timed.points, FlightLimits.of(cfg), 0.0).feasible


@pytest.mark.parametrize('yaw', [0, 60, 120, 180, 240, 300])
@pytest.mark.parametrize('pitch', [-20, 0, 25])
def test_the_plan_leaves_along_the_heading_within_the_limits(yaw, pitch):
    box, field, _ = _crossing()
    cfg = PlannerConfig()
    start = np.array([100.0, 100.0, 50.0])
    static = plan(field, start, [190.0, 180.0, 60.0], box, cfg)
    h = unit_heading([yaw, pitch])
    entry = enter(static.path, h, box, FlightLimits.of(cfg))
    first = entry.points[1] - entry.points[0]
    assert np.linalg.norm(np.cross(first / np.linalg.norm(first), h)) < 1e-9
    assert first @ h > 0
    assert entry.feasible
    assert check_limits(entry.points, FlightLimits.of(cfg), 0.0).feasible
    # Only the turn-in is new; the path beyond it is the plan's own vertices.
    tail = len(entry.points) - entry.changed - 1
    assert 1 <= tail < len(static.path)
    assert np.array_equal(entry.points[-tail:], static.path[-tail:])
    # ...and the turn-in is no detour: turning back at R = 10 m flies about (pi + 2) R
    # more, 26 of the plan's 61 at w 0.5; within 35 % of the plan's J.
    j = path_cost(entry.points, field.positions, field.intensities, cfg.w).J
    assert j <= 1.35 * path_cost(static.path, field.positions, field.intensities, cfg.w).J


def test_the_turn_in_is_flown_at_the_turn_radius_at_most():
    """Straight back: the pursuit turns at (1.02 x) the turn radius, never tighter."""
    box, field, _ = _crossing()
    cfg = PlannerConfig()
    start = np.array([100.0, 100.0, 50.0])
    static = plan(field, start, [190.0, 180.0, 60.0], box, cfg)
    back = -(static.path[1] - static.path[0])
    entry = enter(static.path, back / np.linalg.norm(back), box,
                  FlightLimits.of(cfg))
    assert entry.feasible and entry.turn_deg == pytest.approx(180.0, abs=1e-6)
    radii = turn_radii(entry.points)
    assert radii.min() >= cfg.min_turn_radius_m * (1 - 1e-9)
    # A U-turn of radius R reaches about 2 R sideways: it does not stay within R of start.
    assert np.linalg.norm(entry.points - start, axis=1).max() > 1.5 * cfg.min_turn_radius_m


def test_a_plan_already_on_the_heading_is_kept():
    box, field, _ = _crossing()
    cfg = PlannerConfig()
    static = plan(field, [10.0, 100, 50], [190.0, 100, 50], box, cfg)
    h = static.path[1] - static.path[0]
    entry = enter(static.path, h / np.linalg.norm(h), box,
                  FlightLimits.of(cfg))
    assert entry.changed == 0 and np.array_equal(entry.points, static.path)


def test_headings_from_vectors_and_angles():
    assert unit_heading([3.0, 4.0, 0.0]) == pytest.approx([0.6, 0.8, 0.0])
    assert unit_heading([90.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-15)
    h = unit_heading([45.0, 30.0])
    assert math.degrees(math.asin(h[2])) == pytest.approx(30.0)
    for bad, msg in (([0, 0, 0], 'zero vector'), ([1.0, np.nan, 0], 'finite'),
                     ([1.0], 'expected')):
        with pytest.raises(InputError, match=f'start_heading: .*{msg}'):
            unit_heading(bad)


def test_a_turn_in_that_would_leave_the_box_is_ranked_not_raised():
    """Climbing at the box's ceiling: every pursuit leaves it, and none may be kept as
    feasible; the least-bad path comes back (it used to raise ValueError: no limit was
    broken, so the ranking of violations had nothing to rank)."""
    box, field, _ = _crossing()
    cfg = PlannerConfig()
    start = np.array([100.0, 100.0, 99.9])
    static = plan(field, start, [190.0, 180.0, 60.0], box, cfg)
    entry = enter(static.path, unit_heading([200.0, 25.0]), box,
                  FlightLimits.of(cfg))
    inside = np.all(entry.points >= box.lo - 1e-9) and np.all(entry.points <= box.hi + 1e-9)
    assert entry.feasible == (inside and check_limits(entry.points, FlightLimits.of(cfg),
                                                      0.0).feasible)
