"""bench large_fields: its scenario files hold the fresh field, its verdicts follow the numbers."""

import numpy as np

from bench.suites.large_fields import child, markdown, npy_scenario, summary, TARGETS
from bench.toolkit.fresh_fields import make_field
from threat_planner import load_scenario


def test_the_npy_scenario_is_the_fresh_field(tmp_path):
    path = npy_scenario(300, 7, 1, tmp_path)
    sc = load_scenario(path)
    field = make_field('uniform', 300, 7, 1)
    np.testing.assert_array_equal(sc.threats.positions, field.positions)
    np.testing.assert_array_equal(sc.threats.intensities, field.intensities)
    np.testing.assert_array_equal(sc.start, field.start)
    np.testing.assert_array_equal(sc.box.hi, field.hi)


def _raw(plan_ms: float, cli_ms: float, rss: float) -> dict:
    field = {'plan_ms': [plan_ms] * 3, 'delaunay_ms': 200.0, 'J': 1.0, 'feasible': True,
             'stages_ms': {}}
    return {'10000': {'HEAD': [field, field]},
            '10000 cli': [{'wall_ms': cli_ms, 'delaunay_ms': 200.0, 'peak_rss_mib': 300.0}],
            '20': {'HEAD': [{'case_ms': [5.0, 6.0, 30.0]}]},
            '100000': {'plan_ms': [9000.0], 'delaunay_ms': 3000.0, 'J': 2.0, 'feasible': True,
                       'stages_ms': {}},
            '100000 cli': {'wall_ms': 12000.0, 'plan_ms': 7500.0, 'peak_rss_mib': rss,
                           'J': 2.0, 'feasible': True}}


def test_each_verdict_is_its_number_against_its_target():
    met = summary(_raw(590.0, 1100.0, 2000.0), ['HEAD'])['verdicts']
    assert set(met) == set(TARGETS) and all(v['met'] for v in met.values())
    assert met['10000 CLI / Delaunay']['value'] == 5.5
    assert met['100000 plan() / Delaunay']['value'] == 2.5     # the CLI's plan(), not cProfile's
    missed = summary(_raw(610.0, 1300.0, 5000.0), ['HEAD'])['verdicts']
    assert [k for k, v in missed.items() if not v['met']] == [
        '10000 warm plan() ms', '10000 CLI / Delaunay', '100000 peak RSS MiB']
    text = markdown(summary(_raw(610.0, 1300.0, 5000.0), ['HEAD']),
                    {'command': 'c', 'date': 'd', 'seed': 1, 'machine': 'm', 'load': 'l',
                     'trees': 't', 'fields': 2, 'repeats': 3}, ['HEAD'])
    assert '| 10000 warm plan() ms <= 600 | 610.00 | **MISSED** |' in text


def test_the_child_measures_a_real_plan(capsys):
    child('{"kind": "field", "n": 100, "seed": 3, "k": 0, "repeats": 1}')
    import json
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out['feasible'] and len(out['plan_ms']) == 1 and out['delaunay_ms'] > 0
    assert out['J'] > 0 and 'total_ms' in out['stages_ms']
