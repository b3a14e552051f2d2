"""The parallel kernels' OpenMP wait policy: plans on a quiet machine and beside busy loops.

numba's ``omp`` threading layer (GNU libgomp here) lets a worker thread spin after each
parallel loop before it sleeps (``OMP_WAIT_POLICY`` unset: a while; ``ACTIVE``: always).
The L-BFGS of a problem above ``_aot.PARALLEL_PAIRS`` runs thousands of short parallel
loops a plan, and on a machine whose cores are taken (CI's two test workers, the other
nodes of a vehicle) the spinning thread holds a core the working one needs: one run of
plans beside two busy loops took 1.1-2.4 s a 1,000-threat plan against 0.10-0.15 s with
``OMP_WAIT_POLICY=PASSIVE``. This suite plans fresh uniform fields
(:func:`bench.toolkit.fresh_fields.uniform`) of 100, 1,000 and 10,000 threats, w 0.5,
default limits, each policy in its own fresh process, taking turns, quiet and beside two
busy loops. The column ``package`` is the process as the package leaves it (spin
``_numba_cache.SPIN_COUNT`` times, then sleep: :func:`threat_planner.core._numba_cache.
configure`); ``libgomp default`` is what it did before (spin 300,000 times); ``PASSIVE``
never spins, ``ACTIVE`` always. A first run (seed 1796649451, one process a cell) also
had spin counts of 30,000 (erratic beside the busy loops: 2.1 s at 100 threats, 6.2 s at
10,000) and 3,000 (quiet as fast as libgomp's default: 53 / 153 / 613 ms against 56 /
151 / 633 ms at 100 / 1,000 / 10,000 threats; beside the busy loops 250 / 303 / 2,044 ms
against 203 / 7,116 / 1,891 ms), which the package took. Writes
``bench/results/omp_wait.{md,json}``.

Usage: ``python -m bench omp_wait [--rounds R] [--seed S]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from bench.toolkit.repo import command, machine, RESULTS, ROOT

BUSY = 'import time\nt = time.time() + 900\nwhile time.time() < t: pass'
SIZES = (100, 1000, 10_000)
#: Policy -> what a process's environment gets ({}: the package's own setting). An empty
#: OMP_WAIT_POLICY is invalid to libgomp, which then keeps its default (spin
#: GOMP_SPINCOUNT = 300,000 times before sleeping), and it stops the package's own
#: setting (a value that is there stands).
POLICIES = {'package': {}, 'libgomp default': {'OMP_WAIT_POLICY': ''},
            'PASSIVE': {'OMP_WAIT_POLICY': 'PASSIVE'}, 'ACTIVE': {'OMP_WAIT_POLICY': 'ACTIVE'}}
CHILD = '''
import json, sys, time
from bench.toolkit.fresh_fields import make_field
from threat_planner import plan, PlannerConfig
import os
n, seed, repeats = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
f = make_field('uniform', n, seed, 0)
threats, s, t, box = f.problem()
plan(threats, s, t, box, PlannerConfig(w=0.5))
times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    r = plan(threats, s, t, box, PlannerConfig(w=0.5))
    times.append(1e3 * (time.perf_counter() - t0))
print(json.dumps({'ms': times, 'J': r.cost.J, 'policy': os.environ.get('OMP_WAIT_POLICY')}))
'''


def run(n: int, seed: int, repeats: int, policy: dict) -> dict:
    """Plan in a fresh process with the variables of `policy` (none: the package's own)."""
    env = {k: v for k, v in os.environ.items() if k not in ('OMP_WAIT_POLICY', 'GOMP_SPINCOUNT')}
    env.update(policy, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, '-c', CHILD, str(n), str(seed), str(repeats)],
                          env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def measure(rounds: int, seed: int, repeats: int) -> dict:
    """Every (load, size, policy), the policies taking turns."""
    out: dict = {}
    for load in ('quiet', 'beside 2 busy loops'):
        busy = [] if load == 'quiet' else [
            subprocess.Popen([sys.executable, '-c', BUSY]) for _ in range(2)]
        try:
            for n in SIZES:
                for _ in range(rounds):
                    for name, policy in POLICIES.items():
                        row = run(n, seed, repeats, policy)
                        out.setdefault(load, {}).setdefault(str(n), {}).setdefault(
                            name, []).append(row)
        finally:
            for p in busy:
                p.kill()
    return out


def markdown(raw: dict, meta: dict) -> str:
    """Return the report: median plan ms per load, size and policy."""
    lines = ['# OpenMP wait policy of the parallel kernels', '',
             f"`{meta['command']}` on {meta['date']}, seed {meta['seed']}, {meta['machine']}; "
             f"each cell the median over {meta['rounds']} fresh processes x {meta['repeats']} "
             'warm plans (fresh uniform fields, w 0.5, default limits); the policies took '
             'turns. `package` = spin 3,000 times, then sleep (the package\'s own setting); '
             '`libgomp default` = spin 300,000 times, as before it.', '',
             '| load | threats | ' + ' | '.join(POLICIES) + ' | J the same |',
             '|---|---:|' + '---:|' * len(POLICIES) + '---|']
    for load, sizes in raw.items():
        for n, rows in sizes.items():
            cells = [statistics.median(ms for r in rows[p] for ms in r['ms']) for p in POLICIES]
            same = len({r['J'] for p in POLICIES for r in rows[p]}) == 1
            lines.append(f'| {load} | {n} | ' + ' | '.join(f'{c:.0f} ms' for c in cells)
                         + f" | {'yes' if same else 'NO'} |")
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Measure and write the results."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--rounds', type=int, default=2)
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--seed', type=int)
    ap.add_argument('--out', default=str(RESULTS / 'omp_wait.md'))
    args = ap.parse_args(argv)
    seed = args.seed if args.seed is not None else int(time.time()) % 2**31
    raw = measure(args.rounds, seed, args.repeats)
    meta = {'command': command('omp_wait', sys.argv[1:] if argv is None else argv),
            'date': time.strftime('%Y-%m-%d %H:%M'), 'seed': seed, 'machine': machine(),
            'rounds': args.rounds, 'repeats': args.repeats}
    text = markdown(raw, meta)
    with open(args.out, 'w') as f:
        f.write(text)
    with open(os.path.splitext(args.out)[0] + '.json', 'w') as f:
        json.dump({'meta': meta, 'raw': raw}, f, indent=1)
    print(text)
    return 0
