"""scipy imported through :mod:`threat_planner.core._scipy_first`: numpy's unused submodules
stay unloaded, numpy works as ever afterwards, and plans are the same bit for bit."""

import json
from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / 'test' / 'data' / 'uniform20_0.yaml'

LOADED = r"""
import json, sys, types
import {first}
import numpy
loaded = sorted(n for n in ('f2py', 'testing', 'ma', 'polynomial') if 'numpy.' + n in sys.modules)
compat = sys.modules['scipy._lib.array_api_compat.numpy']
out = {{'loaded': loaded,
        'close': compat.testing.assert_allclose is not None,   # the stand-in loads it
        'module': isinstance(numpy.f2py, types.ModuleType),   # numpy's own loader again
        'same': compat.testing.assert_allclose is numpy.testing.assert_allclose}}
print(json.dumps(out))
"""

PLAN = r"""
import json, sys
{first}
from threat_planner.core import load_scenario, plan, PlannerConfig
sc = load_scenario(sys.argv[1])
r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5))
print(json.dumps({{'J': r.cost.J, 'path': r.path.tolist()}}))
"""


def _run(code: str, *args: str) -> dict:
    p = subprocess.run([sys.executable, '-c', code, *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_the_planner_loads_scipy_without_numpy_s_unused_submodules():
    out = _run(LOADED.format(first='threat_planner.core.network.partition'))
    assert out == {'loaded': [], 'close': True, 'module': True, 'same': True}


def test_the_check_can_fail_scipy_alone_loads_them():
    """scipy's own import (1.17) loads them: the module above is what keeps them out."""
    out = _run(LOADED.format(first='scipy.spatial'))
    assert out['loaded'] == ['f2py', 'ma', 'polynomial', 'testing'], out


def test_plans_are_the_same_with_scipy_imported_plainly_first():
    ours = _run(PLAN.format(first=''), str(SCENARIO))
    plain = _run(PLAN.format(first='import scipy.spatial, scipy.sparse, scipy.optimize'),
                 str(SCENARIO))
    assert ours == plain
