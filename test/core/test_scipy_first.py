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


FIRST_PLAN = r"""
import json, sys
from threat_planner.core import load_scenario, plan, PlannerConfig
sc = load_scenario(sys.argv[1])
r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=0.5))
import numpy
ma_loaded = 'numpy.ma' in sys.modules
numpy.ma.masked_array([1.0], mask=[True])      # numpy's loader answers again
from scipy.spatial import Delaunay
try:
    Delaunay(numpy.ma.masked_array(numpy.eye(4)[:, :3], mask=False))
    refused = False
except ValueError:
    refused = True
print(json.dumps({'ma': ma_loaded, 'blas': 'threadpoolctl' in sys.modules,
                  'refused': refused, 'J': r.cost.J}))
"""


def test_a_first_plan_imports_neither_numpy_ma_nor_the_blas_scan():
    """Delaunay's masked-array check and np.median each imported numpy.ma (12-14 ms of a
    first plan), and the BLAS scan took 6-9 ms; a masked input is still refused after."""
    out = _run(FIRST_PLAN, str(SCENARIO))
    assert out['ma'] is False and out['blas'] is False and out['refused'] is True, out


def test_unmasked_answers_as_numpy_ma_once_it_is_loaded():
    import numpy as np
    import numpy.ma
    from threat_planner.core._scipy_first import unmasked
    with unmasked():
        assert np.ma is numpy.ma
        assert np.ma.isMaskedArray(np.ma.masked_array([1.0]))
        assert not np.ma.isMaskedArray(np.zeros(2))


THREADS = r"""
import json, sys, threading
import numpy as np
from threat_planner.core._scipy_first import unmasked
loader = np.__dict__['__getattr__']
barrier = threading.Barrier(4)
seen = []

def hold():
    with unmasked():
        barrier.wait(timeout=10)
        with unmasked():
            seen.append(np.ma.isMaskedArray(np.zeros(2)))
        barrier.wait(timeout=10)
threads = [threading.Thread(target=hold) for _ in range(4)]
for t in threads:
    t.start()
for t in threads:
    t.join(timeout=30)
print(json.dumps({'restored': np.__dict__['__getattr__'] is loader, 'seen': seen,
                  'ma': 'numpy.ma' in sys.modules}))
"""


def test_unmasked_nests_and_restores_numpy_s_loader_from_threads():
    out = _run(THREADS)
    assert out == {'restored': True, 'seen': [False] * 4, 'ma': False}
