"""``python -m bench fresh``: its field families and its gate, without planning anything."""

import importlib
import math
from pathlib import Path
import sys

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
ff = importlib.import_module('bench.toolkit.fresh_fields')
fr = importlib.import_module('bench.toolkit.fresh_report')
fresh = importlib.import_module('bench.suites.fresh')

#: Sizes small enough for a unit test (the generators are numpy only; no plan is made).
SIZES = (20, 300, 3000)
ARRAYS = ('positions', 'intensities', 'start', 'goal', 'lo', 'hi')


@pytest.mark.parametrize('family', sorted(ff.FAMILIES))
def test_each_family_is_the_same_field_under_the_same_seed_and_another_under_another(family):
    a, b = ff.make_field(family, 300, 11, 1), ff.make_field(family, 300, 11, 1)
    assert all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ARRAYS)
    for other in (ff.make_field(family, 300, 12, 1), ff.make_field(family, 300, 11, 0)):
        assert not np.array_equal(a.positions, other.positions)


@pytest.mark.parametrize('family', sorted(ff.FAMILIES))
@pytest.mark.parametrize('n', SIZES)
def test_each_family_gives_n_threats_inside_its_box_clear_of_start_and_goal(family, n):
    f = ff.make_field(family, n, 5)
    side = ff.side_of(n)
    assert f.positions.shape == (n, 3) and f.intensities.shape == (n,)
    assert np.all(f.intensities > 0) and np.all(np.isfinite(f.positions))
    assert np.allclose(f.lo, 0.0) and np.allclose(f.hi, side)
    assert np.all(f.positions >= f.lo) and np.all(f.positions <= f.hi)
    for end in (f.start, f.goal):
        assert np.all(end >= f.lo) and np.all(end <= f.hi)
        assert np.linalg.norm(f.positions - end, axis=1).min() >= 0.05 * side - 1e-9
    threats, s, t, box = f.problem()
    assert len(threats) == n and box.contains(s) and box.contains(t)


def test_the_families_have_their_shapes():
    n = 3000
    side = ff.side_of(n)
    ground = ff.make_field('ground', n, 3)
    assert ground.positions[:, 2].max() <= 0.1 * side
    assert min(ground.start[2], ground.goal[2]) >= 0.2 * side
    weak = ff.make_field('strongweak', n, 3).intensities
    assert weak.max() / weak.min() > 30 and np.sum(weak >= 1e6) == n // 20
    flat = ff.make_field('coplanar', n, 3).positions
    centred = flat - flat.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False) / math.sqrt(n)
    assert spread[2] < 0.01 * side < 0.1 * side < spread[1]
    uniform = ff.make_field('uniform', n, 3)
    assert np.allclose(uniform.start, [0, 0, side / 2])
    assert np.allclose(uniform.goal, [side, side, side / 2])
    assert uniform.intensities.min() >= 1e5 and uniform.intensities.max() <= 4e5


def test_a_case_name_reads_back():
    case = {'family': 'coplanar', 'n': 10000, 'k': 1, 'w': 0.5, 'limits': 'on'}
    assert fresh.parse_id(fresh.case_id(**case)) == case
    with pytest.raises(ValueError):
        fresh.parse_id('nosuch-n20-f0-w0.5-on')
    cases = fresh.cases((20, 100), ('uniform', 'ground'), 2, (0.2, 0.8))
    assert len(cases) == 2 * 2 * 2 * 2 * 2
    assert len({fresh.case_id(**c) for c in cases}) == len(cases)


def _row(i, head, base=1.0, in_box=None, limited=None, limits='on', feasible=True):
    return {'id': f'case{i}', 'family': 'uniform', 'n': 20, 'k': 0, 'w': 0.5,
            'limits': limits,
            'head': {'J': head, 'feasible': feasible, 'own_J': head, 'own_feasible': feasible,
                     'ms': 10.0},
            'base': {'J': base, 'feasible': True, 'own_J': base, 'own_feasible': True,
                     'ms': 10.0},
            'in_box': None if in_box is None else {'J': in_box},
            'limited': None if limited is None else {'J': limited}}


def _good(count=300):
    half = count // 2
    return ([_row(i, 1.0, limited=1.0) for i in range(half)]
            + [_row(half + i, 1.0, in_box=1.0, limits='off') for i in range(count - half)])


def test_the_gate_passes_when_every_line_holds():
    lines = fr.gate(_good())
    assert [ok for ok, _ in lines] == [True] * 4
    assert all(text.endswith('PASS') for _, text in lines)


def test_the_gate_flags_one_case_just_above_the_baseline():
    rows = _good()
    rows[7] = _row(7, 1.0011, limited=1.0011)
    (_, cases), (ok, text), (lim_ok, _), (box_ok, _) = fr.gate(rows)
    assert not ok and '1 of 300 cases above 1.001' in text and 'case7' in text
    assert lim_ok and box_ok   # one case at 1.0011 moves neither median nor worst > 1.01
    rows[7] = _row(7, 1.0009, limited=1.0009)
    assert fr.gate(rows)[1][0]


def test_the_gate_flags_infeasible_plans_too_few_cases_and_missed_yardsticks():
    rows = _good()
    rows[3] = _row(3, 0.9, feasible=False, limited=1.0)
    lines = fr.gate(rows)
    assert not lines[1][0] and 'infeasible by the independent check: 1 of 300' in lines[1][1]
    assert not lines[2][0] and 'worst inf' in lines[2][1]
    assert not fr.gate(_good(299))[0][0]
    rows = _good()
    rows[200] = _row(200, 1.0, in_box=0.99, limits='off')   # 1.0101 of the yardstick
    assert not fr.gate(rows)[3][0]
    rows = _good()
    rows[0] = _row(0, 1.0, limited=1.02)   # a yardstick above HEAD is fine
    ok, text = fr.gate(rows)[2]
    assert ok and '1 below 1' in text


def test_a_baseline_that_failed_the_check_is_not_a_yardstick():
    row = _row(0, 2.0, base=1.0)
    row['base']['feasible'] = False
    assert fr.ratio(row, 'base') is None
    assert fr.badness(row) == 0.0
    assert fr.worst_cases([row], seed=5)[2].endswith('--seed 5 --only case0` |')


def test_a_case_above_the_baseline_is_kept_as_a_scenario_that_loads_back(
        tmp_path, monkeypatch):
    from threat_planner.core.inputs.scenario import load_scenario
    monkeypatch.setattr(fresh, 'REGRESSIONS', tmp_path)
    rows = [{**_row(0, 1.002), 'family': 'ground', 'n': 20, 'id': 'ground-n20-f0-w0.5-on'},
            {**_row(1, 1.5, limits='off'), 'family': 'coplanar', 'n': 1000},
            _row(2, 1.001)]
    written = fresh.keep_regressions(rows, 9, 'head', 'base')
    assert [p.name for p in written] == ['fresh_s9_ground_n20_f0_w0p5_on.yaml',
                                         'fresh_s9_coplanar_n1000_f0_w0p5_off.yaml']
    assert (tmp_path / 'fresh_s9_coplanar_n1000_f0.npy').exists()
    for path, (family, n) in zip(written, (('ground', 20), ('coplanar', 1000))):
        sc, f = load_scenario(path), ff.make_field(family, n, 9)
        assert np.array_equal(sc.threats.positions, f.positions)
        assert np.array_equal(sc.threats.intensities, f.intensities)
        assert np.array_equal(sc.start, f.start) and np.array_equal(sc.goal, f.goal)
    assert '--seed 9 --only ground-n20-f0-w0.5-on' in load_scenario(written[0]).description
