"""bench/suites/perturbation.py: the move is what it says, and the report counts what moved."""

import importlib
from pathlib import Path
import sys

import numpy as np

from threat_planner.core.world.threats import ThreatField

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
rp = importlib.import_module('bench.suites.perturbation')


def test_every_threat_moves_by_the_size_and_keeps_its_intensity():
    rng = np.random.default_rng(0)
    field = ThreatField.from_arrays(rng.uniform(0, 100, (50, 3)), rng.uniform(1, 9, 50))
    for size in rp.MOVES:
        moved = rp.nudged(field, 3, size)
        step = np.linalg.norm(moved.positions - field.positions, axis=1)
        np.testing.assert_allclose(step, size, rtol=1e-5)
        assert np.array_equal(moved.intensities, field.intensities)
        assert np.array_equal(rp.nudged(field, 3, size).positions, moved.positions)  # seeded
        assert not np.array_equal(rp.nudged(field, 4, size).positions, moved.positions)


def _row(case, limits, ratios, warm=True, warm_j=10.0, cold_j=10.0):
    return {'case': case, 'limits': limits, 'J': 10.0, 'ms': 5.0, 'seed': 'route 0',
            'ratios': {'1e-09': ratios[0], '0.001': ratios[1]},
            'seeds_moved': {'1e-09': ['route 0'] * 3, '0.001': ['route 1'] * 3},
            'warm': warm, 'warm_note': 'warm' if warm else 'cold: x', 'warm_ms': 2.0,
            'warm_J': warm_j, 'cold_J': cold_j}


def test_the_report_counts_cases_and_plans_that_moved_and_warm_replans():
    rows = [_row('a@0.2', 'on', ([1.0, 1.2, 0.99], [1.0, 1.0, 1.0])),
            _row('b', 'on', ([1.0, 1.0005, 1.0], [1.0, 0.9, 1.0]), warm_j=10.1),
            _row('a@0.2', 'off', ([1.0, 1.0, 1.0], [1.0, 1.0, 1.0]), warm=False)]
    text = rp.markdown(rows)
    # worse: ratio above 1.001 (a at 1 nm); moved: either way (a at 1 nm, b at 1 mm).
    assert '| on | 1e-09 | 2 | 1 | 1 | 1 | 1 | 1.0000 | 0.9900 | 1.2000 |' in text
    assert '| on | 0.001 | 2 | 0 | 1 | 0 | 1 | 1.0000 | 0.9000 | 1.0000 |' in text
    assert '| off | 1e-09 | 1 | 0 | 0 | 0 | 0 | 1.0000 | 1.0000 | 1.0000 |' in text
    # b's warm J is above its cold J: warm, but not counted as no higher.
    assert '| on | 2 | 1 | 2 | 1 | 1 | 1 | 2.0 |' in text
    assert '| off | 1 | 1 | 0 | 0 | 0 | 0 | nan |' in text
    listed = [line for line in text.splitlines() if line.startswith('| a@0.2 |')]
    assert len(listed) == 1 and '1.0000 / 1.2000 / 0.9900 ; 1.0000' in listed[0]


def test_the_arithmetic_table_lists_the_cases_whose_unmoved_plan_differs():
    host = [_row('a@0.2', 'on', ([1.0] * 3, [1.0] * 3)), _row('b', 'on', ([1.0] * 3, [1.0] * 3))]
    other = [dict(host[0]), dict(host[1], J=10.05, seed='surface route 1')]
    lines = rp.arithmetic_table(host, other)
    other[1]['ratios'] = {'1e-09': [1.0, 1.0, 1.1], '0.001': [1.0] * 3}
    lines = rp.arithmetic_table(host, other)
    assert '2 cases: J bit for bit the same in 1; more than 0.001 apart in 1; other / host ' \
           'from 1.0000 to 1.0050. Moved plans: ratio bit for bit the same in 11 of 12.' in lines
    assert lines[-1] == '| b | on | 10.000 | 10.050 | 1.0050 | route 0 | surface route 1 |'
    assert rp.arithmetic_table(host, [_row('c', 'on', ([1.0] * 3, [1.0] * 3))]) == []
    for row, loop in zip(host + other, ([1.0, 1.0], [1.0, 1.1], [1.0, 1.0], [1.0, 1.2])):
        row.update(loop_ratios=loop, loop_warm=[True] * 2, loop_ms=[1.0] * 2)
    assert rp.arithmetic_table(host, other)[3].endswith(
        'Replans in a loop: ratio bit for bit the same in 3 of 4.')
    assert 'unmoved plans on both' in rp.markdown(other, arithmetic='other', against=host)


def test_the_other_arithmetic_reaches_numpy_and_numba_in_the_child():
    """The variables are read at import: a child started with them runs without AVX-512
    loops in numpy and compiles numba's kernels for a generic x86-64."""
    import os
    import subprocess
    probe = ('import numpy, numba\n'
             'from numpy._core._multiarray_umath import __cpu_features__ as f\n'
             'print(f.get("X86_V4", False), f.get("AVX512_ICL", False), '
             'numba.config.CPU_NAME)')
    out = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                         env={**os.environ, **rp.OTHER_ARITHMETIC}, check=True).stdout
    assert out.split() == ['False', 'False', 'generic']


def test_the_loop_table_counts_warm_replans_above_the_target():
    rows = [dict(_row('a@0.2', 'on', ([1.0] * 3, [1.0] * 3)), loop_ratios=[1.0, 1.002, 0.99],
                 loop_warm=[True, True, False], loop_ms=[1.0, 3.0, 9.0]),
            dict(_row('b', 'on', ([1.0] * 3, [1.0] * 3)), loop_ratios=[1.0005, 1.0, 1.0],
                 loop_warm=[True] * 3, loop_ms=[2.0, 2.0, 2.0])]
    lines = rp.loop_table(rows)
    assert '| on | 6 | 5 | 1 | 1 | 0.9900 | 1.0020 | 2.0 |' in lines
    assert not any(line.startswith('| off |') for line in lines)
    # Rows of a run before the loop was measured (an --against file) give no table.
    assert rp.loop_table([_row('a@0.2', 'on', ([1.0] * 3, [1.0] * 3))]) == []
    assert 'Replans in a loop' in rp.markdown(rows)
