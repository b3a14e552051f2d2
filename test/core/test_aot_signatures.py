"""The committed export signatures: the workload's own, and an early build kept only if so.

``threat-planner compile`` builds the AOT module from :mod:`._aot_signatures` beside the
JIT workload (53 s instead of 97 s here) and keeps it only if the workload's signatures are
those; otherwise it builds again from the workload's manifest.
"""

import json
import os
import subprocess
import sys

import pytest

from threat_planner.core import _aot, compiled
from threat_planner.core._aot_signatures import SIGNATURES

CHECK = r"""
import json
from numba.core.typing import signature
from threat_planner.core import _aot_signatures, aot_build, compiled
cur = compiled.export_signatures()
disp, sigs = compiled._dispatchers(), compiled._read_manifest()
exact = all(signature(aot_build.parse_type(r), *map(aot_build.parse_type, a))
            == disp[q].overloads[sigs[q][0]].signature
            for q, (r, a) in _aot_signatures.SIGNATURES.items())
try:
    aot_build.parse_type('list(int64)')
    refused = False
except ValueError:
    refused = True
with open(_aot_signatures.__file__) as f:
    text = f.read() == aot_build.signatures_module(cur)
print(json.dumps({'equal': cur == _aot_signatures.SIGNATURES, 'exact': exact, 'text': text,
                  'refused': refused, 'exports': len(cur)}))
"""


def test_the_committed_signatures_are_the_workload_s():
    """If this fails after a kernel's types changed: ``python -m
    threat_planner.core.aot_build --signatures > threat_planner/core/_aot_signatures.py``
    (the build would otherwise run twice in every compile, and never use a stale module)."""
    env = dict(os.environ, THREAT_PLANNER_AOT='0')
    p = subprocess.run([sys.executable, '-c', CHECK], env=env, capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out == {'equal': True, 'exact': True, 'text': True, 'refused': True,
                   'exports': len(_aot.quals())}


def _early(staging, code: int) -> subprocess.Popen:
    """A stand-in for the early build's child: its report line, its exit status."""
    staging.mkdir(parents=True)
    (staging / _aot.STAMP).write_text('{}')
    (staging / 'marker').write_text('early')
    line = f'built the AOT kernels (17 exports) in 1 s into {staging}'
    return subprocess.Popen([sys.executable, '-c', f'print({line!r}); raise SystemExit({code})'],
                            stdout=subprocess.PIPE, text=True)


@pytest.mark.parametrize('case', ['fits', 'other types', 'build failed'])
def test_an_early_build_is_kept_only_if_it_built_with_the_workload_s_signatures(
        tmp_path, monkeypatch, case):
    monkeypatch.setenv('THREAT_PLANNER_CACHE_DIR', str(tmp_path / 'cache'))
    final = _aot.aot_dir()
    staging = final.parent / '.staged-test'
    workload = dict(SIGNATURES)
    if case == 'other types':
        first = next(iter(workload))
        workload[first] = ('float64', ('array(float32, 2d, C)',))
    monkeypatch.setattr(compiled, 'export_signatures', lambda: workload)
    proc = _early(staging, 1 if case == 'build failed' else 0)

    def from_manifest(code, timeout):   # the build from the workload's manifest
        return subprocess.CompletedProcess([], 0, f'built the AOT kernels again into {final}\n',
                                           '')
    monkeypatch.setattr(compiled, '_child', from_manifest)
    line = compiled.build_aot((proc, staging))
    assert not staging.exists()
    if case == 'fits':
        assert line == (f'built the AOT kernels (17 exports) in 1 s into {final}, beside the '
                        'JIT workload')
        assert (final / 'marker').read_text() == 'early'
    else:
        assert line == f'built the AOT kernels again into {final}' and not final.exists()
