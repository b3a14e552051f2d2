"""The yardstick table (bench/toolkit/yardstick_table.py): sources, checks, refusals."""

import importlib
import json
from pathlib import Path
import sys

import numpy as np
import pytest

from threat_planner.core.cost.closed_form import path_cost
from threat_planner.core.inputs.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
yd = importlib.import_module('bench.toolkit.yardstick_table')
DATA = Path(__file__).resolve().parents[1] / 'data'
W = 0.5


@pytest.fixture(scope='module')
def sc():
    return load_scenario(DATA / 'weak20_0.yaml')


def _entry(sc, path, j=None, limited=None):
    """A yardstick.json entry whose in-box and limited paths are ``path`` (or ``limited``)."""
    j = path_cost(path, sc.threats.positions, sc.threats.intensities, W).J if j is None else j
    lim_path = path if limited is None else limited
    lim_j = path_cost(lim_path, sc.threats.positions, sc.threats.intensities, W).J
    return {'settings': {'grid': 41},
            'in_box': {'J': j, 'path': np.asarray(path).tolist()},
            'limited': {'J': lim_j, 'feasible': True, 'path': np.asarray(lim_path).tolist(),
                        'limits': {'max_climb_deg': 30.0, 'max_dive_deg': 30.0,
                                   'min_turn_radius_m': 10.0}}}


def _table(tmp_path, cache: dict, ref_box: dict | None = None):
    (tmp_path / 'yardstick.json').write_text(json.dumps(cache))
    (tmp_path / 'reference_box').mkdir(exist_ok=True)
    for key, (j, path) in (ref_box or {}).items():
        np.save(tmp_path / 'reference_box' / f'{key}.npy', path)
    (tmp_path / 'reference_box.json').write_text(
        json.dumps({k: {'J': j} for k, (j, _) in (ref_box or {}).items()}))
    return yd.YardstickTable(tmp_path / 'yardstick.json', tmp_path / 'reference_box.json')


def test_bench_value_first_reference_box_as_check_and_fallback(tmp_path, sc):
    line = np.array([sc.start, sc.goal])
    j = path_cost(line, sc.threats.positions, sc.threats.intensities, W).J
    table = _table(tmp_path, {f'{sc.name}@{W}': _entry(sc, line)},
                   {f'{sc.name}@{W}': (j, line), f'{sc.name}@0.8': (
                       path_cost(line, sc.threats.positions, sc.threats.intensities, 0.8).J,
                       line)})
    y = table.get(sc, W)
    assert y.in_box == pytest.approx(j) and y.in_box_source == 'bench 41^3'
    assert y.box_check == pytest.approx(1.0) and y.limited == pytest.approx(j)
    assert y.limits.min_turn_radius_m == 10.0
    other = table.get(sc, 0.8)
    assert other.in_box_source == 'reference_box.json' and other.limited is None
    assert table.get(sc, 0.2).in_box is None


def test_a_path_leaving_the_box_or_a_wrong_j_is_refused(tmp_path, sc):
    out = np.array([sc.start, sc.box.hi + 5.0, sc.goal])
    with pytest.raises(ValueError, match='leaves the box'):
        _table(tmp_path, {f'{sc.name}@{W}': _entry(sc, out)}).get(sc, W)
    line = np.array([sc.start, sc.goal])
    with pytest.raises(ValueError, match='stored J'):
        _table(tmp_path, {f'{sc.name}@{W}': _entry(sc, line, j=1.0)}).get(sc, W)


def test_a_limited_path_breaking_its_limits_is_refused(tmp_path, sc):
    # One metre across and twenty up (or down, at the box top): far beyond 30 deg.
    up = 20.0 if sc.start[2] + 20.0 <= sc.box.hi[2] else -20.0
    mid = sc.box.clip(sc.start + np.array([1.0, 1.0, up]) * np.sign(sc.goal - sc.start + 1e-9))
    steep = np.array([sc.start, mid, sc.goal])
    assert not yd.check_limits(steep, yd.Limits(30.0, 30.0, 10.0))
    with pytest.raises(ValueError, match='breaks its limits'):
        _table(tmp_path, {f'{sc.name}@{W}': _entry(sc, np.array([sc.start, sc.goal]),
                                                   limited=steep)}).get(sc, W)


def test_committed_yardsticks_load_and_agree_with_reference_box():
    table = yd.YardstickTable()
    for key in table.cache:
        name, _, w = key.rpartition('@')
        y = table.get(load_scenario(DATA / f'{name}.yaml'), float(w))
        if y.box_check is not None:
            assert abs(y.box_check - 1.0) < 1e-3, key


def test_score_case_checks_the_limits_row_independently(sc):
    rb = importlib.import_module('bench.suites.benchmark')
    br = importlib.import_module('bench.toolkit.benchmark_report')
    line = np.array([sc.start, sc.goal])
    j = path_cost(line, sc.threats.positions, sc.threats.intensities, W).J
    up = 20.0 if sc.start[2] + 20.0 <= sc.box.hi[2] else -20.0
    spike = np.array([sc.start, sc.box.clip(sc.start + [1.0, 1.0, up]), sc.goal])
    y = yd.Yardsticks(j / 1.01, 'bench 41^3', 1.0, j, yd.Limits(30.0, 30.0, 10.0), j * 0.9)
    case = {'methods': {br.ON: {'J': j, 'path': line.tolist()},
                        br.OFF: {'J': j, 'path': (line + [0.0, 0.0, 1e3]).tolist()}}}
    rb.score_case(case, sc, y)
    on, off = case['methods'][br.ON], case['methods'][br.OFF]
    assert on['ratio'] == pytest.approx(1.01) and on['ratio_limited'] == pytest.approx(1.0)
    assert on['limits_ok'] and on['worst_violation'] == '' and on['in_box']
    assert not off['in_box'] and case['yardsticks']['in_box_source'] == 'bench 41^3'
    case['methods'][br.ON]['path'] = spike.tolist()
    rb.score_case(case, sc, y)
    assert not case['methods'][br.ON]['limits_ok']
    assert 'vs 30' in case['methods'][br.ON]['worst_violation']
