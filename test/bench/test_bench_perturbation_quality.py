"""python -m bench perturbation --quality: the gate's table counts what rose and what fell."""

import importlib
from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
rp = importlib.import_module('bench.suites.perturbation')


def test_the_quality_table_counts_higher_lower_and_equal_plans():
    before = {'a@0.2 on': [100.0, True, 'route 0'], 'a@0.2 off': [90.0, True, 'route 0'],
              'b@0.5 on': [50.0, True, 'route 1'], 'c@0.8 on': [10.0, True, 'route 2']}
    after = {'a@0.2 on': [100.0, True, 'route 0'],
             'a@0.2 off': [90.0 * (1 + 0.5 * rp.QUALITY_SLACK), True, 'route 0'],
             'b@0.5 on': [50.1, True, 'route 3'], 'c@0.8 on': [9.9, False, 'route 2']}
    text = rp.quality_markdown(before, after, ('old', 'new'))
    # a rise within the slack is not "higher"; 50 -> 50.1 is; 10 -> 9.9 is lower
    assert 'plans: 4; higher than before by more than 1e-06 relative: 1 (b@0.5 on); ' \
           'lower: 1; bit for bit the same J: 1' in text
    assert '| b@0.5 | on | 50.000000 | 50.100000 | 1.0020000 | True / True | route 3 |' in text
    assert '| c@0.8 | on | 10.000000 | 9.900000 | 0.9900000 | True / False | route 2 |' in text
