"""The newest numba on PyPI beside the pinned one: the bundled 20-threat cases in both.

setup.py pins numba to the minor release tested here. This suite says what a user who
upgrades numba would get: it builds a throwaway venv in a temporary folder (no system
site packages), installs the newest numba into it with the project venv's numpy, scipy,
PyYAML and threadpoolctl (or, where that numba refuses them, with what pip picks, which
the report then names), and puts this checkout on its ``PYTHONPATH`` (``pip install .``
would hold numba to the pin this row steps past). Then one worker process in that venv
and one in the project's venv plan the bundled cases (:data:`SCENARIOS` at every w of
:data:`WS`, default settings, limits on), taking turns case by case.

Both run the JIT path (``THREAT_PLANNER_AOT=0``: the AOT module is built by the project
venv's numba) with an empty kernel cache each, so the first pass includes each numba's
compile. Reported: the versions, per case J in both and their ratio, whether path and J
agree bit for bit, and the times. Writes ``bench/results/numba_newest.md``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

from bench.toolkit.cases import SCENARIOS, WS
from bench.toolkit.checkouts import short_commit
from bench.toolkit.repo import command, DATA, machine, RESULTS, ROOT

#: The packages the planning core imports, besides numba, pinned in the throwaway venv to
#: the project venv's versions so that a difference is numba's.
SAME_AS_PROJECT = ('numpy', 'scipy', 'PyYAML', 'threadpoolctl')

WORKER = r'''
import hashlib, json, sys, time
t0 = time.perf_counter()
import llvmlite, numba, numpy, scipy
import threat_planner
from threat_planner import load_scenario, plan, PlannerConfig
print(json.dumps({'numba': numba.__version__, 'llvmlite': llvmlite.__version__,
                  'numpy': numpy.__version__, 'scipy': scipy.__version__,
                  'package': threat_planner.__file__,
                  'imports_s': time.perf_counter() - t0}), flush=True)
for line in sys.stdin:
    case = json.loads(line)
    sc = load_scenario(case['file'])
    t1 = time.perf_counter()
    r = plan(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=case['w']))
    ms = 1e3 * (time.perf_counter() - t1)
    print(json.dumps({'ms': ms, 'J': r.cost.J.hex(), 'feasible': bool(r.feasible),
                      'path': hashlib.sha256(r.path.tobytes()).hexdigest()}), flush=True)
'''


def _run(cmd: list[str], **kw) -> str:
    p = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL, **kw)
    if p.returncode != 0:
        raise RuntimeError(f'{" ".join(cmd)} failed:\n{p.stdout[-1500:]}{p.stderr[-3000:]}')
    return p.stdout


def project_versions() -> dict[str, str]:
    """Return the project venv's versions of :data:`SAME_AS_PROJECT` (distribution names)."""
    import importlib.metadata
    return {name: importlib.metadata.version(name) for name in SAME_AS_PROJECT}


def newest_on_pypi(python: Path) -> str:
    """Return the newest numba release pip sees ('?' where pip cannot say)."""
    try:
        out = _run([str(python), '-m', 'pip', 'index', 'versions', 'numba'], timeout=120)
    except (RuntimeError, subprocess.TimeoutExpired):
        return '?'
    first = out.strip().splitlines()[0] if out.strip() else ''
    return first.partition('(')[2].rstrip(')') or '?'


def build_venv(where: Path, numba_spec: str) -> tuple[Path, str, float]:
    """Make the throwaway venv with `numba_spec`; its python, how it was pinned, seconds."""
    t0 = time.perf_counter()
    # The base interpreter, not the project venv's: the new venv must not see its packages.
    base = getattr(sys, '_base_executable', sys.executable)
    _run([base, '-m', 'venv', str(where)], timeout=300)
    python = where / 'bin' / 'python'
    pins = [f'{k}=={v}' for k, v in project_versions().items()]
    pip = [str(python), '-m', 'pip', 'install', '--quiet', '--disable-pip-version-check',
           '--upgrade']
    try:
        _run(pip + [numba_spec, *pins], timeout=1800)
        how = 'with the project venv\'s ' + ', '.join(pins)
    except RuntimeError as exc:
        print(f'numba_newest: {numba_spec} refused the pins, letting pip choose: {exc}',
              file=sys.stderr)
        _run(pip + [numba_spec, *SAME_AS_PROJECT], timeout=1800)
        how = 'with what pip chose for ' + ', '.join(SAME_AS_PROJECT) + \
              ' (the project venv\'s versions conflict with this numba)'
    return python, how, time.perf_counter() - t0


class Worker:
    """A planning process: one interpreter, this checkout, a kernel cache of its own."""

    def __init__(self, python: Path, cache: Path) -> None:
        env = dict(os.environ, PYTHONPATH=str(ROOT), THREAT_PLANNER_AOT='0',
                   THREAT_PLANNER_CACHE_DIR=str(cache))
        env.pop('NUMBA_CACHE_DIR', None)
        self.proc = subprocess.Popen([str(python), '-c', WORKER], env=env, text=True,
                                     cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self.info = json.loads(self.proc.stdout.readline())
        assert self.info['package'].startswith(str(ROOT)), self.info['package']

    def plan(self, case: dict) -> dict:
        """Plan one case: its ms, J (float.hex), feasibility and the path's hash."""
        self.proc.stdin.write(json.dumps(case) + '\n')
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self) -> None:
        """End the worker (its input closed)."""
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def cases() -> list[dict]:
    """Return the bundled 20-threat cases: every scenario at every w."""
    return [{'name': f'{name}@{w}', 'file': str(DATA / f'{name}.yaml'), 'w': w}
            for name in SCENARIOS for w in WS]


def measure(workers: dict[str, Worker], repeats: int) -> tuple[dict, list[dict]]:
    """First pass (compiles) per worker in turn, then `repeats` turns on every case."""
    first = {}
    for label, w in workers.items():
        t0 = time.perf_counter()
        for case in cases():
            w.plan(case)
        first[label] = time.perf_counter() - t0
    rows = []
    for i, case in enumerate(cases()):
        runs: dict[str, list[dict]] = {label: [] for label in workers}
        for k in range(max(repeats, 1)):
            order = list(workers) if (i + k) % 2 == 0 else list(workers)[::-1]
            for label in order:
                runs[label].append(workers[label].plan(case))
        row = {'case': case['name']}
        for label, got in runs.items():
            # Deterministic plans: a J that moved between repeats would be a bug to see.
            assert len({(r['J'], r['path']) for r in got}) == 1, (case, label, got)
            row[label] = dict(got[0], ms=statistics.median(r['ms'] for r in got))
        rows.append(row)
        print(case['name'], ' '.join(f"{label} {float.fromhex(row[label]['J']):.6f} "
                                     f"{row[label]['ms']:.1f} ms" for label in workers),
              flush=True)
    return first, rows


def report(info: dict, first: dict, rows: list[dict], meta: dict) -> str:
    """Markdown of one run: versions, then per case J, ratio, bit for bit, times."""
    a, b = 'pinned', 'newest'
    same = info[a]['numba'] == info[b]['numba']

    def j(row, label):
        return float.fromhex(row[label]['J'])

    exact = [r for r in rows if (r[a]['J'], r[a]['path']) == (r[b]['J'], r[b]['path'])]
    ratios = [j(r, b) / j(r, a) for r in rows]
    ms_a = statistics.median(r[a]['ms'] for r in rows)
    ms_b = statistics.median(r[b]['ms'] for r in rows)
    lines = [f"# numba: the newest on PyPI beside the pinned one ({meta['date']}, "
             f"{meta['commit']})", '',
             f"`{command('numba_newest')}`; {machine()}; the {len(rows)} bundled 20-threat "
             f"cases ({', '.join(SCENARIOS)} at w {'/'.join(map(str, WS))}), default "
             f"settings, the JIT path in both, {meta['repeats']} turns per case (ms = the "
             "median), the two worker processes taking turns.", '',
             '| | numba | llvmlite | numpy | scipy |', '|---|---|---|---|---|']
    lines += [f"| {label} ({where}) | {info[label]['numba']} | {info[label]['llvmlite']} | "
              f"{info[label]['numpy']} | {info[label]['scipy']} |"
              for label, where in ((a, 'the project venv, setup.py\'s pin'),
                                   (b, 'a throwaway venv'))]
    lines += ['', f"Newest numba on PyPI as pip sees it: {meta['pypi']}. The throwaway "
              f"venv was built {meta['how']} in {meta['venv_s']:.0f} s."]
    if same:
        lines += ['', f"**The newest numba is the pinned one ({info[a]['numba']})**: this "
                  'run shows the row works and that two fresh installs of it agree; it '
                  'says nothing yet about a newer release.']
    lines += ['', f'| case | J {a} | J {b} | {b}/{a} | bit for bit | feasible | '
              f'ms {a} | ms {b} | {b}/{a} ms |', '|---|---:|---:|---:|---|---|---:|---:|---:|']
    for r, ratio in zip(rows, ratios):
        same_bits = 'yes' if r in exact else ('J' if r[a]['J'] == r[b]['J'] else 'no')
        lines.append(f"| {r['case']} | {j(r, a):.6f} | {j(r, b):.6f} | {ratio:.6f} | "
                     f"{same_bits} | {r[a]['feasible']}/{r[b]['feasible']} | "
                     f"{r[a]['ms']:.1f} | {r[b]['ms']:.1f} | {r[b]['ms'] / r[a]['ms']:.2f} |")
    lines += ['',
              f'* Bit for bit (J and every path coordinate): {len(exact)} of {len(rows)} '
              'cases.',
              f'* J {b}/{a}: median {statistics.median(ratios):.6f}, lowest {min(ratios):.6f}, '
              f'highest {max(ratios):.6f}.',
              f'* Warm plan, median over the cases: {ms_a:.1f} ms {a}, {ms_b:.1f} ms {b} '
              f'({ms_b / ms_a:.2f}x).',
              f"* First pass over the cases with an empty cache (the kernels' compile): "
              f"{first[a]:.1f} s {a}, {first[b]:.1f} s {b}; imports {info[a]['imports_s']:.2f}"
              f" s and {info[b]['imports_s']:.2f} s."]
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Build the venv, plan in both, write the report."""
    ap = argparse.ArgumentParser(prog=command('numba_newest'), description=__doc__)
    ap.add_argument('--numba', default='numba',
                    help='what pip installs in the throwaway venv (default: the newest)')
    ap.add_argument('--repeats', type=int, default=5, help='turns per case (default 5)')
    ap.add_argument('--out', type=Path, default=RESULTS / 'numba_newest.md')
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='numba_newest_') as tmp:
        work = Path(tmp)
        python, how, venv_s = build_venv(work / 'venv', args.numba)
        meta = {'date': time.strftime('%Y-%m-%d'), 'commit': short_commit(ROOT),
                'repeats': args.repeats, 'how': how, 'venv_s': venv_s,
                'pypi': newest_on_pypi(python)}
        workers = {'pinned': Worker(Path(sys.executable), work / 'cache_pinned'),
                   'newest': Worker(python, work / 'cache_newest')}
        try:
            first, rows = measure(workers, args.repeats)
        finally:
            for w in workers.values():
                w.close()
    text = report({k: w.info for k, w in workers.items()}, first, rows, meta)
    args.out.write_text(text)
    print(text)
    return 0
