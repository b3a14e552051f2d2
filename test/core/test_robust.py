"""Robust plans: the mean J over sampled pictures is the J on their merged field."""

from pathlib import Path

from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays
import numpy as np
import pytest

from threat_planner import load_scenario, path_cost, PlannerConfig, plan, ThreatField
from threat_planner.core.robust import (merged_field, picture_costs, plan_robust,
                                        sample_pictures, Uncertainty)
from threat_planner.errors import InputError

DATA = Path(__file__).resolve().parents[1] / 'data'


def _mean_exact_j(points, pictures, w):
    """Mean of the closed-form J over the pictures, one picture at a time."""
    return float(np.mean([path_cost(points, p.positions, p.intensities, w).J
                          for p in pictures]))


@pytest.mark.parametrize('name,w', [('weak20_0', 0.5), ('uniform20_0', 0.8)])
def test_robust_j_is_the_mean_exact_j_over_its_pictures(name, w):
    sc = load_scenario(DATA / f'{name}.yaml')
    u = Uncertainty(position_sigma_m=5.0, intensity_sigma=0.2)
    cfg = PlannerConfig(w=w)
    result = plan_robust(sc.threats, sc.start, sc.goal, sc.box, cfg, 6, u, seed=[3, 1],
                         holdout=False)
    pictures = sample_pictures(sc.threats, 6, u, [3, 1], antithetic=True)
    assert result.cost.J == pytest.approx(_mean_exact_j(result.path, pictures, w), rel=1e-12)
    merged = merged_field(pictures)
    assert len(merged) == 6 * len(sc.threats)
    on_merged = path_cost(result.path, merged.positions, merged.intensities, w)
    assert result.cost.J == pytest.approx(on_merged.J, rel=1e-12)
    assert result.feasible
    # No worse than either start it had: the planner's plan of the merged field and the
    # nominal plan's path.
    direct = plan(merged, sc.start, sc.goal, sc.box, cfg)
    nominal = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    assert result.cost.J <= direct.cost.J * (1 + 1e-12)
    assert result.cost.J <= _mean_exact_j(nominal.path, pictures, w) * (1 + 1e-12)
    assert set(result.timings_ms) == {'merged_plan_ms', 'nominal_plan_ms', 'refine_ms',
                                      'total_ms'}


@pytest.mark.parametrize('name,w', [('weak20_0', 0.5), ('weak20_0', 0.8), ('uniform20_0', 0.8)])
def test_a_path_fitted_to_its_pictures_must_also_win_on_pictures_held_out(name, w):
    """The robust path is the nominal plan's, or lower than it on pictures K..2K-1 too
    (weak20_0 at w 0.5 here: the merged plan is 0.2 % lower on its 6 pictures, higher on
    the 6 held out, and the nominal path is kept)."""
    sc = load_scenario(DATA / f'{name}.yaml')
    u = Uncertainty(position_sigma_m=5.0, intensity_sigma=0.2)
    cfg = PlannerConfig(w=w)
    result = plan_robust(sc.threats, sc.start, sc.goal, sc.box, cfg, 6, u, seed=[3, 1])
    nominal = plan(sc.threats, sc.start, sc.goal, sc.box, cfg)
    held_out = sample_pictures(sc.threats, 6, u, [3, 1], first=6, antithetic=True)
    pictures = sample_pictures(sc.threats, 6, u, [3, 1], antithetic=True)
    assert result.cost.J == pytest.approx(_mean_exact_j(result.path, pictures, w), rel=1e-12)
    if np.array_equal(result.path, nominal.path):
        assert result.seed.endswith(('held out', 'unrefined')) or 'nominal' in result.seed
    else:
        fitted = _mean_exact_j(result.path, held_out, w)
        assert fitted < _mean_exact_j(nominal.path, held_out, w)


@settings(max_examples=40, deadline=None)
@given(k=st.integers(1, 6), n=st.integers(1, 8), seed=st.integers(0, 2**31),
       w=st.floats(0.05, 0.95),
       path=arrays(float, (5, 3), elements=st.floats(-50, 150, allow_nan=False)))
def test_mean_j_over_pictures_equals_j_on_the_merged_field(k, n, seed, w, path):
    rng = np.random.default_rng(seed)
    threats = ThreatField.from_arrays(rng.uniform(0, 100, (n, 3)), rng.uniform(1e3, 1e5, n))
    pictures = sample_pictures(threats, k, Uncertainty(8.0, 0.5), seed)
    merged = merged_field(pictures)
    mean = _mean_exact_j(path, pictures, w)
    whole = path_cost(path, merged.positions, merged.intensities, w).J
    assert whole == pytest.approx(mean, rel=1e-9)
    each = picture_costs(path, pictures, w)
    for c, p in zip(each, pictures):
        exact = path_cost(path, p.positions, p.intensities, w)
        assert c.J == pytest.approx(exact.J, rel=1e-12) and c.J_L == pytest.approx(exact.J_L)


def test_pictures_spread_as_asked_and_picture_i_never_depends_on_the_count():
    sc = load_scenario(DATA / 'weak20_0.yaml')
    u = Uncertainty(position_sigma_m=5.0, intensity_sigma=0.3)
    many = sample_pictures(sc.threats, 300, u, 11)
    moves = np.stack([p.positions - sc.threats.positions for p in many])
    ratios = np.log(np.stack([p.intensities / sc.threats.intensities for p in many]))
    # 18,000 coordinate draws and 6,000 intensity draws: a few per cent either way.
    assert moves.std() == pytest.approx(5.0, rel=0.03) and abs(moves.mean()) < 0.1
    assert ratios.std() == pytest.approx(0.3, rel=0.05) and abs(ratios.mean()) < 0.02
    few = sample_pictures(sc.threats, 4, u, 11)
    later = sample_pictures(sc.threats, 2, u, 11, first=3)
    for a, b in ((few[3], many[3]), (later[0], many[3]), (later[1], many[4])):
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.intensities, b.intensities)
    pairs = sample_pictures(sc.threats, 300, u, 11, antithetic=True)
    np.testing.assert_array_equal(pairs[0].positions, many[0].positions)
    for a, b in zip(pairs[0::2], pairs[1::2]):
        np.testing.assert_allclose(a.positions + b.positions, 2 * sc.threats.positions,
                                   rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(a.intensities * b.intensities, sc.threats.intensities ** 2,
                                   rtol=1e-12)
    moved = np.stack([p.positions - sc.threats.positions for p in pairs[1::2]])
    assert moved.std() == pytest.approx(5.0, rel=0.05)     # each picture spreads alike
    other = sample_pictures(sc.threats, 1, u, 12)[0]
    assert not np.array_equal(other.positions, many[0].positions)
    still = sample_pictures(sc.threats, 3, Uncertainty(), 11)
    assert all(np.array_equal(p.positions, sc.threats.positions) and
               np.array_equal(p.intensities, sc.threats.intensities) for p in still)


@pytest.mark.parametrize('call,needle', [
    (lambda: Uncertainty(position_sigma_m=-1.0), 'position_sigma_m: must be a finite'),
    (lambda: Uncertainty(intensity_sigma=float('inf')), 'intensity_sigma: must be a finite'),
    (lambda: sample_pictures(ThreatField.from_arrays([[1, 2, 3]], [1.0]), 0, Uncertainty()),
     'samples: must be an integer >= 1'),
    (lambda: sample_pictures(ThreatField.from_arrays([[1, 2, 3]], [1.0]), 2, Uncertainty(),
                             seed=-3), 'seed: must be an integer >= 0'),
    (lambda: merged_field([]), 'pictures: need at least one'),
])
def test_bad_arguments_name_the_field(call, needle):
    with pytest.raises(InputError, match=needle):
        call()
