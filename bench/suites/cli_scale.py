"""``threat-planner plan`` on 10,000 threats against a bare ``scipy.spatial.Delaunay``.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python -m bench cli_scale                 # 3 repeats, ~2 min
    .venv/bin/python -m bench cli_scale --repeats 1 -- --max-climb 20

Target (issue 11): the whole command, loading included, takes at most 8x a bare Delaunay
of the same points. One run measures, alternating so that the load of a shared machine
hits every row alike:

* **Delaunay**: ``scipy.spatial.Delaunay(points)`` on the 10,000 threat positions, in this
  process, after the points are in memory (the bare triangulation the planner cannot skip);
* **plan, YAML**: ``python -m threat_planner.cli plan scale10000.yaml`` as a fresh process
  (interpreter start, imports, YAML loading, validation, ``plan``, printing);
* **plan, threats_file .npy / .csv**: the same scenario with its threats in a compact file
  next to the YAML (scenario key ``threats_file``), written to a temporary folder.

The package is byte-compiled first, as pip and colcon install it. For every command:
median wall time, the planner's own ``time:`` line (so the rest is
start-up and loading), peak RSS of the child (``wait4``), and ratio to the Delaunay median.
Writes ``bench/results/cli_scale.{md,json}``.
"""

from __future__ import annotations

import argparse
import compileall
import datetime as dt
import json
import os
from pathlib import Path
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.spatial import Delaunay
import yaml

from bench.toolkit.repo import command, RESULTS, ROOT, SHARED

SCENARIO = SHARED / 'scale10000.yaml'
TARGET_RATIO = 8.0
_TIME = re.compile(r'time: ([0-9.]+) ms')


def split_scenario(yaml_path: Path, folder: Path) -> dict[str, Path]:
    """Write the scenario with its threats in a .npy and in a .csv file; return the YAMLs."""
    from threat_planner.core.inputs.scenario import load_scenario, save_scenario
    sc = load_scenario(yaml_path)
    out = {}
    for suffix in ('npy', 'csv'):
        path = folder / f'{yaml_path.stem}_{suffix}.yaml'
        save_scenario(sc, path, f'threats.{suffix}')
        out[f'plan, threats_file .{suffix}'] = path
    return out


def run_cli(scenario: Path, extra: list[str]) -> dict:
    """Run ``threat-planner plan`` once as a fresh process; wall [ms], plan ms, peak RSS."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, '-m', 'threat_planner.cli', 'plan', str(scenario), *extra]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, env=env)
        # wait4 reaps the child itself and returns its own rusage (peak RSS of this run).
        _, status, rusage = os.wait4(proc.pid, 0)
        wall = 1e3 * (time.perf_counter() - t0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text, error = out.read().decode(), err.read().decode()
    if proc.returncode:
        raise RuntimeError(f'{" ".join(cmd)} failed: {error.strip()}')
    match = _TIME.search(text)
    return {'wall_ms': wall, 'plan_ms': float(match.group(1)) if match else float('nan'),
            'peak_rss_mib': rusage.ru_maxrss / 1024, 'J': _final_j(text)}


def _final_j(text: str) -> float:
    match = re.search(r'final:\s+J=([0-9.eE+-]+)', text)
    return float(match.group(1)) if match else float('nan')


def fresh_import_ms() -> dict:
    """Wall time [ms] of a fresh ``python -c pass`` and of importing the CLI."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = {}
    for label, code in (('python start', 'pass'),
                        ('python start + import the CLI', 'import threat_planner.cli.main')):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, '-c', code], check=True, env=env)
        out[label] = 1e3 * (time.perf_counter() - t0)
    return out


def load_ms(paths: dict[str, Path]) -> dict:
    """In-process ``load_scenario`` wall time [ms] per file (validation included)."""
    from threat_planner.core.inputs.scenario import load_scenario
    out = {}
    for label, path in paths.items():
        t0 = time.perf_counter()
        load_scenario(path)
        out[label] = 1e3 * (time.perf_counter() - t0)
    return out


def measure(repeats: int, extra: list[str]) -> dict:
    """Run every row ``repeats`` times, interleaved; return the raw measurements."""
    doc = yaml.load(SCENARIO.read_bytes(), Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    points = np.array([t['position'] for t in doc['threats']], float)
    rows: dict[str, list] = {'Delaunay': []}
    loads: dict[str, list] = {}
    starts: dict[str, list] = {}
    with tempfile.TemporaryDirectory(prefix='cli_scale_') as tmp:
        commands = {'plan, YAML': SCENARIO, **split_scenario(SCENARIO, Path(tmp))}
        for label in commands:
            rows[label] = []
        for _ in range(repeats):
            for label, ms in load_ms(commands).items():
                loads.setdefault(label.replace('plan, ', ''), []).append(ms)
            for label, ms in fresh_import_ms().items():
                starts.setdefault(label, []).append(ms)
            t0 = time.perf_counter()
            Delaunay(points)
            rows['Delaunay'].append({'wall_ms': 1e3 * (time.perf_counter() - t0)})
            for label, path in commands.items():
                rows[label].append(run_cli(path, extra))
    return {'rows': rows, 'load_ms': {k: statistics.median(v) for k, v in loads.items()},
            'start_ms': {k: statistics.median(v) for k, v in starts.items()}}


def summarise(rows: dict) -> list[dict]:
    """Median per row and ratio to the Delaunay median."""
    base = statistics.median(r['wall_ms'] for r in rows['Delaunay'])
    out = []
    for label, runs in rows.items():
        wall = statistics.median(r['wall_ms'] for r in runs)
        plan_ms = statistics.median(r.get('plan_ms', float('nan')) for r in runs)
        out.append({'row': label, 'wall_ms': wall, 'plan_ms': plan_ms,
                    'rest_ms': wall - plan_ms if label != 'Delaunay' else float('nan'),
                    'ratio': wall / base,
                    'peak_rss_mib': max(r.get('peak_rss_mib', float('nan')) for r in runs),
                    'J': runs[0].get('J'), 'runs_ms': [r['wall_ms'] for r in runs]})
    return out


def markdown(summary: list[dict], meta: dict, parts: dict) -> str:
    """Return the cli_scale.md text."""
    def num(x, fmt='.0f'):
        return '-' if x is None or x != x else format(x, fmt)
    lines = ['# `threat-planner plan` on 10,000 threats', '',
             f"Generated {meta['date']} by `{meta['command']}` on {meta['machine']}; the "
             'machine was shared with other engineers\' jobs (load average '
             f"{meta['load']}), so read the ratios (measured interleaved in one run), not the "
             'absolute times.', '',
             f"Scenario `{SCENARIO.name}` (10,000 threats); options `{meta['extra'] or '-'}`; "
             f"median of {meta['repeats']} runs; the package byte-compiled first, as pip and "
             'colcon install it (this machine sets PYTHONDONTWRITEBYTECODE=1). Every `plan` '
             'row is a fresh process: '
             'interpreter start, imports, loading and validation, `plan()`, printing. '
             '`plan ms` is the planner\'s own `time:` line; `rest` = wall - plan (start-up, '
             'imports, loading). Delaunay = bare `scipy.spatial.Delaunay` of the same points, '
             'in memory.', '',
             '| row | wall ms | plan() ms | rest ms | / Delaunay | (load + plan()) / Delaunay '
             '| peak RSS MiB | J |', '|---|---:|---:|---:|---:|---:|---:|---:|']
    base = summary[0]['wall_ms']
    for r in summary:
        load = parts['load_ms'].get(r['row'].replace('plan, ', ''), float('nan'))
        inner = (load + r['plan_ms']) / base if r['row'] != 'Delaunay' else float('nan')
        lines.append(f"| {r['row']} | {num(r['wall_ms'])} | {num(r['plan_ms'])} | "
                     f"{num(r['rest_ms'])} | {r['ratio']:.2f} | {num(inner, '.2f')} | "
                     f"{num(r['peak_rss_mib'])} | {num(r['J'], '.3f')} |")
    lines += ['', '(load + plan()) leaves out the interpreter start and the imports, which the '
              'target counts (the wall column is the verdict).', '',
              'Where the rest goes (same run, medians): in-process `load_scenario` '
              '(parse + validation) per file, and a fresh interpreter with and without '
              'importing the CLI (numpy, scipy.optimize, numba, the package).', '',
              '| part | ms |', '|---|---:|']
    lines += [f'| load_scenario, {k} | {v:.0f} |' for k, v in parts['load_ms'].items()]
    lines += [f'| {k} | {v:.0f} |' for k, v in parts['start_ms'].items()]
    lines += ['', '| target | value | verdict |', '|---|---:|---|']
    for r in summary[1:]:
        ok = r['ratio'] <= TARGET_RATIO
        lines.append(f"| {r['row']}: wall <= {TARGET_RATIO:g}x Delaunay | {r['ratio']:.2f}x | "
                     f"**{'PASS' if ok else 'MISS'}** |")
    lines.append('')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Measure and write the results; return the exit status."""
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--repeats', type=int, default=3)
    p.add_argument('--out', type=Path, default=RESULTS)
    p.add_argument('extra', nargs='*', help='options passed on to threat-planner plan')
    args = p.parse_args(argv)
    given = sys.argv[1:] if argv is None else argv
    meta = {'date': dt.datetime.now().isoformat(timespec='seconds'),
            'command': command('cli_scale', given),
            'machine': f'{platform.machine()}, {os.cpu_count()} CPUs, '
                       f'Python {platform.python_version()}',
            'load': ', '.join(f'{x:.1f}' for x in os.getloadavg()),
            'repeats': args.repeats, 'extra': ' '.join(args.extra)}
    # Installed as users install it (pip and colcon byte-compile the package): this machine
    # sets PYTHONDONTWRITEBYTECODE=1, so every fresh process would compile the checkout's
    # modules from source (measured: 86 ms of wall time a start).
    meta['bytecode'] = compileall.compile_dir(str(ROOT / 'threat_planner'), quiet=1)
    raw = measure(args.repeats, args.extra)
    summary = summarise(raw['rows'])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'cli_scale.json').write_text(json.dumps(
        {'meta': meta, 'rows': summary, 'load_ms': raw['load_ms'], 'start_ms': raw['start_ms']},
        indent=1))
    text = markdown(summary, meta, raw)
    (args.out / 'cli_scale.md').write_text(text)
    print(text)
    return 0
