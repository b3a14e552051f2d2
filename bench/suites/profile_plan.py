"""Profile ``plan`` (method ``best``) on the bundled 20-threat scenarios with cProfile.

Usage (from the repository root)::

    .venv/bin/python -m bench profile_plan OUT.txt [--config KEY=VALUE ...]

Runs ``plan`` once per scenario and w (0.2, 0.5, 0.8) to warm caches, then profiles
``--repeats`` more passes and writes the wall time per call and the top functions by
cumulative and by own time to OUT.txt.
"""

from __future__ import annotations

import argparse
import cProfile
import io
from pathlib import Path
import pstats
import time

from bench.toolkit.repo import DATA
from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.planner import plan, PlannerConfig

SCENARIOS = ('uniform20_0', 'uniform20_1', 'weak20_0', 'strongweak_0', 'ground_0')
WEIGHTS = (0.2, 0.5, 0.8)


def _value(text: str) -> object:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {'true': True, 'false': False}.get(text.lower(), text)


def main(argv: list[str] | None = None) -> None:
    """Profile and write the report."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('out')
    ap.add_argument('--config', nargs='*', default=[], help='PlannerConfig KEY=VALUE')
    ap.add_argument('--repeats', type=int, default=2)
    args = ap.parse_args(argv)
    extra = {k: _value(v) for k, v in (item.split('=', 1) for item in args.config)}
    problems = [load_scenario(DATA / f'{name}.yaml') for name in SCENARIOS]
    configs = [PlannerConfig(w=w, **extra) for w in WEIGHTS]

    def run_all() -> None:
        for sc in problems:
            for cfg in configs:
                plan(sc.threats, sc.start, sc.goal, sc.box, cfg)

    run_all()
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    for _ in range(args.repeats):
        run_all()
    prof.disable()
    calls = args.repeats * len(problems) * len(configs)
    per_call = 1e3 * (time.perf_counter() - t0) / calls
    out = io.StringIO()
    out.write(f'# plan(best) on {", ".join(SCENARIOS)} x w {WEIGHTS}, config {extra}\n')
    out.write(f'# {calls} calls under cProfile, {per_call:.1f} ms per call (profiled; '
              'machine shared with other engineers)\n\n')
    for key in ('cumulative', 'tottime'):
        pstats.Stats(prof, stream=out).sort_stats(key).print_stats(25)
    Path(args.out).write_text(out.getvalue())
    print(f'{per_call:.1f} ms per call -> {args.out}')
