"""The replan step in flight (core/flight/commit.py): keep commit_s, replan from its end, splice.

The committed stretch is the old trajectory (its vertices bit for bit, its ends on its
segments), the times run on without a gap, and the replan leaves the joint along the
trajectory's direction there within the limits.
"""

from pathlib import Path

import numpy as np
import pytest

from threat_planner.core.flight.commit import commit, replan_in_flight, splice
from threat_planner.core.flight.reference import ReferencePath
from threat_planner.core.flight.replan import plan_in_time
from threat_planner.core.flight.timed_cost import timed_path_cost
from threat_planner.core.flight.timeline import ThreatTimeline
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.errors import InputError

DATA = Path(__file__).resolve().parents[1] / 'data'
SPEED = 20.0


@pytest.fixture(scope='module')
def flight():
    """A first plan on uniform20_0, then a pop-up threat 60 m along it, replanned at 0.5 s."""
    sc = load_scenario(DATA / 'uniform20_0.yaml')
    cfg = PlannerConfig()
    known = ThreatTimeline(sc.threats)
    first = plan_in_time(known, sc.start, sc.goal, sc.box, cfg, SPEED)
    ref = ReferencePath(first.points)
    s_now = 0.5 * SPEED + 0.3          # a little ahead of schedule
    known.add(0.5, ref.at(60.0) + [0.0, 3.0, 0.0], 2e5)
    kept = commit(ref, s_now, 0.5, sc.goal, SPEED, cfg.commit_s)
    out = replan_in_flight(known, kept, sc.box, cfg)
    return sc, cfg, known, ref, kept, out


def test_the_committed_stretch_is_the_old_trajectory(flight):
    _, cfg, _, ref, kept, out = flight
    assert kept.s_end == pytest.approx(kept.s_now + SPEED * cfg.commit_s, abs=1e-12)
    inner = ref.points[(ref.s > kept.s_now) & (ref.s < kept.s_end)]
    assert len(inner) >= 1
    committed = out.points[:out.joint + 1]
    # Its vertices bit for bit, its ends the old trajectory's points at s_now and s_end.
    assert np.array_equal(committed[1:-1], inner)
    assert np.array_equal(committed[0], ref.at(kept.s_now))
    assert np.array_equal(committed[-1], ref.at(kept.s_end))
    assert np.array_equal(committed[-1], kept.end)


def test_times_run_on_without_a_gap(flight):
    _, _, known, _, kept, out = flight
    assert out.times[0] == 0.5
    assert out.times[out.joint] == kept.t_end == out.plan.times[0]
    assert np.array_equal(out.points[out.joint:], out.plan.points)
    assert np.array_equal(out.times[out.joint:], out.plan.times)
    step = np.linalg.norm(np.diff(out.points, axis=0), axis=1)
    assert np.allclose(np.diff(out.times), step / SPEED, rtol=0, atol=1e-12)
    assert np.all(np.diff(out.times) > 0)
    # The replan's reported cost is the exact timed J of its part of the trajectory.
    assert out.plan.cost.J == timed_path_cost(out.plan.points, out.plan.times, known,
                                              PlannerConfig().w).J


def test_the_joint_keeps_the_heading_and_the_limits(flight):
    sc, cfg, _, _, kept, out = flight
    last = out.points[out.joint] - out.points[out.joint - 1]
    first = out.points[out.joint + 1] - out.points[out.joint]
    h = kept.heading
    assert np.linalg.norm(np.cross(last / np.linalg.norm(last), h)) < 1e-12
    assert np.linalg.norm(np.cross(first / np.linalg.norm(first), h)) < 1e-9
    assert first @ h > 0
    assert out.plan.entry is not None and out.plan.entry.feasible
    limits = FlightLimits.of(cfg)
    assert check_limits(out.plan.points, limits, float(sc.box.lo[2])).feasible
    # Through the joint: the committed stretch runs straight into it and the replan
    # leaves along it, so the joint is no corner. The fillets of the turns either side of
    # it (radius R, tangent length R tan(turn / 2)) fit on the straight between them. The
    # limit rule itself fits each fillet in half of each segment, which the cut at the
    # joint shortens: it is met by the replan, from the joint on.
    a, j, b = out.points[out.joint - 1], out.points[out.joint], out.points[out.joint + 1]
    r = cfg.min_turn_radius_m

    def tangent_length(p, q, o):
        u, v = q - p, o - q
        turn = np.arctan2(np.linalg.norm(np.cross(u, v)), u @ v)
        return r * np.tan(turn / 2)
    need = (tangent_length(out.points[out.joint - 2], a, b)
            + tangent_length(a, b, out.points[out.joint + 2]))
    assert need <= np.linalg.norm(b - a)
    assert np.linalg.norm(np.cross(j - a, b - j)) < 1e-9 * np.linalg.norm(b - a) ** 2


def test_a_moved_goal_drops_the_guess_and_a_commit_at_the_goal_is_arriving(flight):
    sc, cfg, _, ref, _, _ = flight
    moved = commit(ref, 10.0, 0.5, sc.goal + [0.0, -5.0, 0.0], SPEED, cfg.commit_s)
    assert moved.guess is None and not moved.arriving
    same = commit(ref, 10.0, 0.5, sc.goal, SPEED, cfg.commit_s)
    assert np.array_equal(same.guess[1:-1], ref.points[ref.s > same.s_end][:-1])
    near = commit(ref, ref.length - 5.0, 7.0, sc.goal, SPEED, cfg.commit_s)
    assert near.arriving and near.s_end == ref.length
    out = replan_in_flight(ThreatTimeline(sc.threats), near, sc.box, cfg)
    assert out.plan is None and np.array_equal(out.points, near.points)
    assert out.times[-1] == pytest.approx(7.0 + 5.0 / SPEED, abs=1e-12)


def test_splice_drops_a_duplicate_joint():
    ref = ReferencePath([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]])
    kept = commit(ref, 2.0, 0.0, [30.0, 0.0, 0.0], 4.0, 2.0)   # ends at s = 10, a vertex
    assert np.array_equal(kept.points, [[2.0, 0, 0], [10.0, 0, 0]])

    class Plan:
        points = np.array([[10.0, 0, 0], [10.0 + 1e-12, 0, 0], [30.0, 0, 0]])
        times = np.array([2.0, 2.0, 7.0])
    out = splice(kept, Plan)
    assert out.points.tolist() == [[2.0, 0, 0], [10.0, 0, 0], [30.0, 0, 0]]
    assert out.joint == 1 and out.times.tolist() == [0.0, 2.0, 7.0]


@pytest.mark.parametrize('speed, commit_s, field', [(0.0, 2.0, 'speed_mps'),
                                                    (20.0, -1.0, 'commit_s'),
                                                    (20.0, float('nan'), 'commit_s')])
def test_bad_speed_or_commit_is_refused_by_name(speed, commit_s, field):
    with pytest.raises(InputError, match=field):
        commit([[0.0, 0, 0], [1.0, 0, 0]], 0.0, 0.0, [1.0, 0, 0], speed, commit_s)
