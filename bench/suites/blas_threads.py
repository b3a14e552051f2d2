"""Does ``plan()`` need BLAS held to one thread? Plans with and without the limit, in turns.

The first commits ran their optimisers in numpy and limited BLAS to one thread inside
``plan()`` (4x faster on a busy machine then). The optimisers now run in compiled kernels;
finding the BLAS libraries to limit cost 6-9 ms of a process's first plan (realpath of
~100 loaded libraries). This suite plans the 21 bundled cases (limits on) and big300_0
plus 1,000 and 5,000 random threats, with ``threadpoolctl``'s one-thread limit and
without, taking turns, on a quiet machine and beside two busy loops (the cores taken, as
in CI's two test workers). Writes ``bench/results/blas_threads.md``. (Speed is not the
only question: plans with an airspace differ with the thread count, so ``plan()`` holds
them to one thread whatever this finds; see ``planner._one_blas_thread``.)

Usage: ``python -m bench blas_threads [--rounds R]``
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import subprocess
import sys
import time

from threadpoolctl import ThreadpoolController

from bench.toolkit.cases import scale_problem, SCENARIOS, WS
from bench.toolkit.repo import command, DATA, machine, RESULTS
from threat_planner import load_scenario, plan, PlannerConfig

BUSY = 'import time\nt = time.time() + 600\nwhile time.time() < t: pass'


def _cases() -> dict[str, list[tuple]]:
    bundled = []
    for name in SCENARIOS:
        sc = load_scenario(DATA / f'{name}.yaml')
        bundled += [(sc.threats, sc.start, sc.goal, sc.box, PlannerConfig(w=w)) for w in WS]
    big = load_scenario(DATA / 'big300_0.yaml')
    large = [(big.threats, big.start, big.goal, big.box, PlannerConfig(w=0.5))]
    large += [(*scale_problem(n, 1), PlannerConfig(w=0.5)) for n in (1000, 5000)]
    return {'21 bundled cases': bundled, 'big300_0, 1,000 and 5,000 threats': large}


def _total(cases: list[tuple], limited: bool, controller: ThreadpoolController) -> float:
    hold = (controller.limit(limits=1, user_api='blas') if limited
            else contextlib.nullcontext())
    start = time.perf_counter()
    with hold:
        for threats, s, t, box, cfg in cases:
            plan(threats, s, t, box, cfg)
    return time.perf_counter() - start


def measure(rounds: int) -> list[dict]:
    """Seconds per pass over each case set, limited and not, quiet and loaded, in turns."""
    controller = ThreadpoolController()
    rows = []
    for load in ('quiet', 'two busy loops'):
        busy = ([subprocess.Popen([sys.executable, '-c', BUSY]) for _ in range(2)]
                if load != 'quiet' else [])
        try:
            for label, cases in _cases().items():
                _total(cases, True, controller)     # kernels loaded, caches warm
                runs: dict[bool, list[float]] = {True: [], False: []}
                for r in range(rounds):
                    for limited in ((True, False) if r % 2 == 0 else (False, True)):
                        runs[limited].append(_total(cases, limited, controller))
                rows.append({'load': load, 'cases': label,
                             'limited': statistics.median(runs[True]),
                             'free': statistics.median(runs[False]),
                             'runs': runs})
                print(rows[-1]['load'], label, f"{rows[-1]['limited']:.3f}",
                      f"{rows[-1]['free']:.3f}", flush=True)
        finally:
            for p in busy:
                p.kill()
    return rows


def main(argv: list[str] | None = None) -> int:
    """Run the suite and write bench/results/blas_threads.md."""
    parser = argparse.ArgumentParser(prog='python -m bench blas_threads')
    parser.add_argument('--rounds', type=int, default=5, help='passes of each setting')
    args = parser.parse_args(argv)
    info = ThreadpoolController().info()
    rows = measure(args.rounds)
    lines = [f'# BLAS threads inside plan() ({time.strftime("%Y-%m-%d")})', '',
             f'`{command("blas_threads", argv or [])}` on {machine()}; BLAS: '
             + ', '.join(f"{i['filepath'].rsplit('/', 1)[-1]} ({i['num_threads']} threads)"
                         for i in info if i['user_api'] == 'blas') + '.',
             f'Median of {args.rounds} passes of each setting, taken in turns; a pass plans '
             'every case of its set once (limits on, method best).', '',
             '| load | cases | one BLAS thread [s] | no limit [s] | no limit / one |',
             '|---|---|---:|---:|---:|']
    lines += [f"| {r['load']} | {r['cases']} | {r['limited']:.3f} | {r['free']:.3f} | "
              f"{r['free'] / r['limited']:.2f} |" for r in rows]
    (RESULTS / 'blas_threads.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    return 0
