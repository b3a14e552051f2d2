"""bench/run_perturbation.py: the nudge is what it says, and the report counts what moved."""

import importlib
from pathlib import Path
import sys

import numpy as np

from threat_planner.core.world.threats import ThreatField

BENCH = Path(__file__).resolve().parents[2] / 'bench'
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))
rp = importlib.import_module('run_perturbation')


def test_every_threat_moves_one_nanometre_and_keeps_its_intensity():
    rng = np.random.default_rng(0)
    field = ThreatField.from_arrays(rng.uniform(0, 100, (50, 3)), rng.uniform(1, 9, 50))
    moved = rp.nudged(field, 3)
    step = np.linalg.norm(moved.positions - field.positions, axis=1)
    np.testing.assert_allclose(step, rp.NUDGE, rtol=1e-5)
    assert np.array_equal(moved.intensities, field.intensities)
    assert np.array_equal(rp.nudged(field, 3).positions, moved.positions)   # seeded
    assert not np.array_equal(rp.nudged(field, 4).positions, moved.positions)


def test_the_report_counts_cases_and_plans_that_moved():
    rows = [{'case': 'a', 'limits': 'on', 'J': 10.0, 'ratios': [1.0, 1.2, 0.99],
             'J_moved': 12.0, 'seed': 'route 0', 'seed_moved': 'route 1'},
            {'case': 'b', 'limits': 'on', 'J': 5.0, 'ratios': [1.0, 1.0005, 1.0],
             'J_moved': 5.0025, 'seed': 'route 0', 'seed_moved': 'route 0'},
            {'case': 'a', 'limits': 'off', 'J': 9.0, 'ratios': [1.0, 1.0, 1.0],
             'J_moved': 9.0, 'seed': 'route 0', 'seed_moved': 'route 0'}]
    text = rp.markdown(rows)
    assert '| on | 2 | 1 | 1 | 1 | 1.0000 | 0.9900 | 1.2000 |' in text
    assert '| off | 1 | 0 | 0 | 0 | 1.0000 | 1.0000 | 1.0000 |' in text
    listed = [line for line in text.splitlines() if line.startswith('| a |')]
    assert len(listed) == 1 and '1.0000 / 1.2000 / 0.9900' in listed[0]
