"""cost_model 'detection': the plan, its bound on P_detect, and its compiled hazard."""

import json
import math

import numpy as np
import pytest

from threat_planner.core.detection.hazard import hazard_and_gradient, layout, path_hazard
from threat_planner.core.detection.kernels import compiled_hazard, swerling0
from threat_planner.core.detection.model import DetectionModel, p_detect_scan
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.optimise.limits import check_limits, FlightLimits
from threat_planner.core.planner import plan
from threat_planner.core.world.threats import Box, ThreatField

DATA = 'test/data/'
MODELS = [DetectionModel(), DetectionModel(swerling=0),
          DetectionModel(rcs_kind='ellipsoid', rcs_values=(3.0, 1.0, 0.5)),
          DetectionModel(swerling=0, rcs_kind='ellipsoid', rcs_values=(3.0, 1.0, 0.5))]


def small_field(seed=3, n=8):
    """A fresh field small enough for a detection plan in well under a second."""
    rng = np.random.default_rng(seed)
    threats = ThreatField.from_arrays(rng.uniform(15.0, 85.0, (n, 3)),
                                      rng.uniform(1e5, 4e5, n))
    box = Box.from_corners([0.0, 0.0, 0.0], [100.0, 100.0, 100.0])
    return threats, np.array([0.0, 0.0, 50.0]), np.array([100.0, 100.0, 50.0]), box


def objective(result, w):
    length = float(np.linalg.norm(np.diff(result.path, axis=0), axis=1).sum())
    l0 = float(np.linalg.norm(result.path[-1] - result.path[0]))
    return w * result.detection.hazard + (1 - w) * length / l0


@pytest.mark.parametrize('model', MODELS, ids=['sw1', 'sw0', 'sw1-ellipsoid', 'sw0-ellipsoid'])
def test_the_compiled_hazard_is_the_numpy_reference(model):
    rng = np.random.default_rng(0)
    pos = rng.uniform(0, 100, (12, 3))
    f = rng.uniform(1e5, 4e5, 12)
    pts = np.linspace([0, 0, 50], [100, 100, 50], 21) + rng.normal(0, 3, (21, 3))
    pts[7] = pos[2]                       # straight through a radar
    lay = layout(pts, pos, f, model)
    ref, gref = hazard_and_gradient(pts, pos, f, model, lay)
    per, grad = compiled_hazard(pts, pos, f, model, lay)
    assert np.allclose(per, ref, rtol=1e-12, atol=1e-300)
    assert np.allclose(grad, gref, rtol=1e-10, atol=1e-14 * np.abs(gref).max())


@pytest.mark.parametrize('p_fa', [0.5, 1e-2, 1e-6, 1e-12])
def test_the_compiled_steady_target_is_ncx2(p_fa):
    snr = np.concatenate([[0.0, 1e-9], np.logspace(-3, 3.5, 40), [1e300]])
    ref, dref = p_detect_scan(snr, p_fa, 0, True)
    mine = np.array([swerling0(s, -math.log(p_fa)) for s in snr])
    assert np.allclose(mine[:, 0], ref, rtol=1e-12, atol=1e-15)
    assert np.allclose(mine[:, 1], dref, rtol=1e-8, atol=1e-15)


@pytest.mark.parametrize('w', [0.2, 0.8])
def test_the_detection_plan_is_never_above_the_paper_plan_and_meets_the_limits(w):
    threats, s, t, box = small_field()
    paper = plan(threats, s, t, box, PlannerConfig(w=w))
    det = plan(threats, s, t, box, PlannerConfig(w=w, cost_model='detection'))
    assert det.cost_model == 'detection' and det.feasible
    check = check_limits(det.path, FlightLimits.of(det.problem[4]), 0.0)
    assert check.feasible
    assert np.all(det.path >= box.lo - 1e-9) and np.all(det.path <= box.hi + 1e-9)
    assert det.objective == pytest.approx(objective(det, w), rel=1e-9)
    assert det.objective <= objective(paper, w) * (1 + 1e-9)
    # The reported J stays the exact paper cost of the path flown.
    length = float(np.linalg.norm(np.diff(det.path, axis=0), axis=1).sum())
    assert det.cost.J_L == pytest.approx(length, rel=1e-12)


def test_where_the_hazard_weighs_it_goes_below_the_paper_plans_p_detect():
    threats, s, t, box = small_field()
    paper = plan(threats, s, t, box, PlannerConfig(w=0.5))
    # H is in expected detections (here ~1e-4) and L / L_0 ~ 1: at w 0.99 the length
    # still outweighs it and the plan is shorter and seen more than the paper's. Only a
    # w that weighs H like the length makes it the least-detected plan.
    shorter = plan(threats, s, t, box, PlannerConfig(w=0.99, cost_model='detection'))
    assert shorter.cost.J_L < paper.cost.J_L
    hidden = plan(threats, s, t, box, PlannerConfig(w=1 - 1e-6, cost_model='detection'))
    assert hidden.detection.p_detect < paper.detection.p_detect


def test_max_detection_gives_the_shortest_path_within_the_bound():
    threats, s, t, box = small_field()
    free = plan(threats, s, t, box, PlannerConfig(w=0.5, cost_model='detection'))
    bound = 0.5 * free.detection.p_detect
    r = plan(threats, s, t, box, PlannerConfig(cost_model='detection', max_detection=bound))
    assert r.detection_status == 'met'
    assert r.detection.p_detect <= bound
    assert r.feasible
    # Within the bound the path is longer than the free plan's, which broke it.
    assert r.cost.J_L > free.cost.J_L
    assert r.summary()['detection']['status'] == 'met'


def test_an_unreachable_bound_is_said_not_silently_broken():
    threats, s, t, box = small_field()
    # Below the false-alarm floor of the straight line: no path can meet it.
    r = plan(threats, s, t, box, PlannerConfig(cost_model='detection', max_detection=1e-9))
    assert r.detection_status.startswith('unmet:')
    assert r.detection.p_detect > 1e-9
    assert 'least P_detect found' in r.summary()['detection']['status']


def test_every_plan_reports_its_detection_in_json():
    sc = load_scenario(DATA + 'uniform20_0.yaml')
    r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig())
    d = json.loads(json.dumps(r.summary()))['detection']
    assert d['P_detect'] == pytest.approx(-math.expm1(-d['H']), rel=1e-12)
    assert len(d['per_threat']) == len(sc.threats)
    assert sum(d['per_threat']) == pytest.approx(d['H'], rel=1e-12)
    exact = path_hazard(r.path, sc.threats.positions, sc.threats.intensities,
                        DetectionModel(speed_mps=r.speed_mps))
    assert d['H'] == pytest.approx(exact.hazard, rel=1e-12)


def test_a_result_with_another_path_reports_that_paths_detection():
    # The in-flight trajectory and a path turned onto a heading are the plan's result with
    # another path (dataclasses.replace): the detection read before must not carry over.
    from dataclasses import replace
    threats, s, t, box = small_field()
    r = plan(threats, s, t, box, PlannerConfig())
    before = r.detection.hazard
    other = replace(r, path=np.vstack([r.path[:3], t]))
    exact = path_hazard(other.path, threats.positions, threats.intensities,
                        DetectionModel(speed_mps=r.speed_mps))
    assert other.detection.hazard == pytest.approx(exact.hazard, rel=1e-12)
    assert other.detection.hazard != pytest.approx(before, rel=1e-6)
    assert r.detection.hazard == before


def test_the_speed_shapes_a_detection_plan_and_not_a_paper_one():
    base = PlannerConfig(cost_model='detection')
    assert not base.plans_like(PlannerConfig(cost_model='detection', speed_mps=5.0))
    assert PlannerConfig().plans_like(PlannerConfig(speed_mps=5.0))
    threats, s, t, box = small_field()
    slow = plan(threats, s, t, box, PlannerConfig(cost_model='detection', speed_mps=2.0))
    fast = plan(threats, s, t, box, PlannerConfig(cost_model='detection', speed_mps=200.0))
    # Slower: more scans per metre, so the hazard weighs more and the path gives way.
    assert slow.detection.hazard / 2.0 * 200.0 >= fast.detection.hazard * (1 - 1e-9)
    assert slow.cost.J_L >= fast.cost.J_L - 1e-6


@pytest.mark.parametrize('name', ['air_spheres_0', 'air_ridges_mask_0'])
def test_zones_and_terrain_stay_hard_for_a_detection_plan(name):
    sc = load_scenario(DATA + name + '.yaml')
    r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(cost_model='detection'),
             airspace=sc.airspace)
    assert sc.airspace.violations(r.path) == []
    assert r.feasible
    if sc.airspace.masking:
        # The report counts only what the radars see.
        bare = path_hazard(r.path, sc.threats.positions, sc.threats.intensities,
                           r.detection_model)
        assert r.detection.hazard < bare.hazard


def test_a_detection_replan_after_a_small_move_is_warm_and_as_good_as_cold():
    threats, s, t, box = small_field()
    cfg = PlannerConfig(cost_model='detection')
    first = plan(threats, s, t, box, cfg)
    moved = ThreatField.from_arrays(threats.positions + 1e-6, threats.intensities)
    warm = plan(moved, s, t, box, cfg, warm_start=first)
    cold = plan(moved, s, t, box, cfg)
    assert warm.warm, warm.warm_note
    assert warm.feasible and warm.cost_model == 'detection'
    assert warm.objective <= cold.objective * (1 + 1e-4)
    # No screening, no paper-cost plan: the previous basin refined again.
    assert 'warm_ms' in warm.timings_ms and 'detection_ms' not in warm.timings_ms
    # A big move plans cold, and says why.
    far = ThreatField.from_arrays(threats.positions + 5.0, threats.intensities)
    again = plan(far, s, t, box, cfg, warm_start=first)
    assert not again.warm and again.warm_note.startswith('cold')


@pytest.mark.parametrize('model', MODELS[2:], ids=['sw1-ellipsoid', 'sw0-ellipsoid'])
def test_a_folded_segment_adds_nothing_and_breaks_nothing(model):
    pos = np.array([[50.0, 10.0, 50.0], [20.0, 60.0, 40.0]])
    f = np.array([2e5, 3e5])
    pts = np.array([[0.0, 0.0, 50.0], [40.0, 0.0, 50.0], [40.0, 0.0, 50.0], [100.0, 0, 50]])
    lay = layout(pts, pos, f, model)
    per, grad = compiled_hazard(pts, pos, f, model, lay)
    ref, gref = hazard_and_gradient(pts, pos, f, model, lay)
    assert np.all(np.isfinite(per)) and np.all(np.isfinite(grad))
    assert np.allclose(per, ref, rtol=1e-12)
    unfolded = np.delete(pts, 2, axis=0)
    assert path_hazard(pts, pos, f, model).hazard == pytest.approx(
        path_hazard(unfolded, pos, f, model).hazard, rel=1e-12)
