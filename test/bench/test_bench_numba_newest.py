"""``python -m bench numba_newest``: its report counts what agrees and says when nothing is new."""

import importlib
from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
nn = importlib.import_module('bench.suites.numba_newest')

META = {'date': '2026-12-06', 'commit': 'abc1234', 'repeats': 5, 'how': 'with pins',
        'venv_s': 16.0, 'pypi': '0.68.1'}


def _info(version):
    return {'numba': version, 'llvmlite': '0.50.0', 'numpy': '2.4.6', 'scipy': '1.17.1',
            'imports_s': 0.7}


def _plan(j, path='p', ms=10.0):
    return {'J': float(j).hex(), 'path': path, 'feasible': True, 'ms': ms}


ROWS = [{'case': 'a@0.5', 'pinned': _plan(100.0), 'newest': _plan(100.0)},
        {'case': 'b@0.5', 'pinned': _plan(100.0), 'newest': _plan(100.0, path='q')},
        {'case': 'c@0.5', 'pinned': _plan(100.0), 'newest': _plan(101.0, path='q', ms=20.0)}]


def test_the_report_counts_bit_for_bit_cases_and_gives_each_ratio():
    text = nn.report({'pinned': _info('0.68.1'), 'newest': _info('0.69.0')},
                     {'pinned': 30.0, 'newest': 31.0}, ROWS, META)
    assert 'Bit for bit (J and every path coordinate): 1 of 3 cases' in text
    assert '| a@0.5 | 100.000000 | 100.000000 | 1.000000 | yes |' in text
    assert '| b@0.5 | 100.000000 | 100.000000 | 1.000000 | J |' in text   # same J, other path
    assert '| c@0.5 | 100.000000 | 101.000000 | 1.010000 | no |' in text
    assert 'highest 1.010000' in text and '| 10.0 | 20.0 | 2.00 |' in text
    assert 'is the pinned one' not in text


def test_the_report_says_when_the_newest_numba_is_the_pinned_one():
    text = nn.report({'pinned': _info('0.68.1'), 'newest': _info('0.68.1')},
                     {'pinned': 30.0, 'newest': 31.0}, ROWS[:1], META)
    assert '**The newest numba is the pinned one (0.68.1)**' in text


def test_the_cases_are_the_bundled_twenty_threat_ones_at_every_w():
    assert len(nn.cases()) == len(nn.SCENARIOS) * len(nn.WS) == 21
    assert all(Path(c['file']).is_file() for c in nn.cases())
