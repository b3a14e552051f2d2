"""A plan is the same on every x86-64 CPU: no BLAS in the planner's arithmetic (issue 28).

OpenBLAS picks its kernels by CPU and each sums in its own order; the planner's products
of vectors went through it (numpy's ``@`` and ``linalg.norm``, numba's ``@``), and a last
bit there sent the constrained rounds elsewhere. Two processes here differ only in the
kernels OpenBLAS runs (``OPENBLAS_CORETYPE``) and in numpy's AVX-512 loops. On 1cdc140
24 of these 31 plans came out with other paths (n20 seed 1 w 0.8: J 399.14 against
395.87; under the Haswell kernels 21 differed); now every J and path is the same bit for
bit. (The airspace method is left out: scipy's SLSQP sums with the CPU's BLAS.)
"""

import json
import os
from pathlib import Path
import platform
import re
import subprocess
import sys

import pytest

PLANS = Path(__file__).with_name('cpu_plans.py')
#: Another OpenBLAS kernel set, runnable on every x86-64 (OPENBLAS_VERBOSE names the one
#: scipy-openblas runs for it Katmai; this CPU's own is SkylakeX) ...
CORETYPE = 'Prescott'
#: ... and numpy without these of its AVX-512 loops, where this CPU has them.
AVX512 = ('X86_V4', 'AVX512_ICL', 'AVX512_SPR')


def _other() -> dict:
    from numpy._core._multiarray_umath import __cpu_features__ as have
    off = [f for f in AVX512 if have.get(f)]
    numpy_off = {'NPY_DISABLE_CPU_FEATURES': ' '.join(off)} if off else {}
    return {'OPENBLAS_CORETYPE': CORETYPE, **numpy_off}


def _plans(extra: dict) -> tuple[dict, str]:
    env = {**os.environ, 'OPENBLAS_VERBOSE': '2', **extra}
    p = subprocess.run([sys.executable, str(PLANS)], capture_output=True, text=True, env=env,
                       timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    cores = set(re.findall(r'Core: (\w+)', p.stderr))
    return json.loads(p.stdout), ','.join(sorted(cores))


@pytest.mark.skipif(platform.machine() not in ('x86_64', 'AMD64'), reason='x86-64 kernels')
def test_plans_are_bit_for_bit_the_same_under_other_blas_kernels():
    here, core = _plans({})
    there, other_core = _plans(_other())
    if core and core == other_core:
        pytest.skip(f'OpenBLAS runs its {core} kernels either way on this CPU')
    assert len(here) == 31 and here.keys() == there.keys()
    differ = [key for key in here if here[key] != there[key]]
    assert not differ, [(key, here[key][0], there[key][0]) for key in differ]
