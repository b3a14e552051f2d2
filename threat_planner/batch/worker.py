"""What a worker process runs: chunks of tasks, each to its rows of the results table.

The same functions run in the local pool's processes and as Ray tasks, so both backends
produce the same rows from the same tasks. A worker stays alive across chunks: the kernels
load at its first plan, and scenarios and evaluation pictures are kept between tasks.
"""

from __future__ import annotations

from functools import lru_cache
import os
import select
import signal
import sys
import threading
import time

from threat_planner.batch.tasks import Task
from threat_planner.core.inputs.scenario import load_scenario, Scenario
from threat_planner.core.planner import plan
from threat_planner.core.robust import picture_costs, plan_robust, sample_pictures, Uncertainty
from threat_planner.core.world.threats import ThreatField
from threat_planner.errors import InputError, PlanningError

__all__ = ['initialise', 'run_chunk', 'run_task']

_STATE = {'ready': False}


def _aot_kernels() -> bool:
    from threat_planner.core import _aot
    return _aot.active()


def initialise(parent: int | None = None) -> None:
    """Set a worker up once: one compute thread, Ctrl-C left to the parent.

    Each worker is one of several processes sharing the cores: numba's and BLAS's own
    threads would only compete with the other workers. With ``parent`` (the pid of the
    ``batch`` run) the worker leaves as soon as that process ends, however it ended: a
    killed run leaves no workers behind (they are children of multiprocessing's fork
    server, which outlives the run as long as they do).
    """
    if _STATE['ready']:
        return
    _STATE['ready'] = True
    # One thread in every library, as Ray sets for its tasks: 1,000 plans on 2 workers
    # took 34-35 s against 25-27 s with OMP_NUM_THREADS=1 in the environment (alternated
    # runs). BLAS was loaded, a thread per core, before this process forked: limited here;
    # OpenMP (numba's threading layer) loads at the first parallel kernel and reads this.
    os.environ['OMP_NUM_THREADS'] = '1'
    from threadpoolctl import threadpool_limits
    threadpool_limits(limits=1)
    if 'numba' in sys.modules or not _aot_kernels():
        # The AOT kernels are serial: numba is imported (and told) only where it runs;
        # its lazily built parallel kernels read OMP_NUM_THREADS above.
        try:
            import numba
            numba.set_num_threads(1)
        except (ImportError, ValueError):  # pragma: no cover - numba is required
            pass
    if parent is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        threading.Thread(target=_leave_with, args=(parent,), daemon=True,
                         name='batch parent watch').start()


def _leave_with(parent: int) -> None:
    """Return never; end this process once ``parent`` has ended."""
    try:
        fd = os.pidfd_open(parent)
    except (AttributeError, OSError):   # no pidfd (old kernel, not Linux): poll
        fd = None
    if fd is not None:
        select.select([fd], [], [])     # readable once the process has ended
    else:
        while True:
            try:
                os.kill(parent, 0)
            except ProcessLookupError:
                break
            except PermissionError:
                pass
            time.sleep(0.5)
    os._exit(1)


def run_chunk(tasks: list[Task]) -> list[dict]:
    """Run tasks one after the other; every row of each, in task order."""
    initialise()
    rows: list[dict] = []
    for task in tasks:
        rows.extend(run_task(task))
    return rows


@lru_cache(maxsize=64)
def _scenario(path: str) -> Scenario:
    return load_scenario(path)


@lru_cache(maxsize=16)
def _evaluation(path: str, samples: int, position_sigma_m: float, intensity_sigma: float,
                seed: tuple[int, ...]) -> list[ThreatField]:
    return sample_pictures(_scenario(path).threats, samples,
                           Uncertainty(position_sigma_m, intensity_sigma), list(seed))


def run_task(task: Task) -> list[dict]:
    """Plan one task and score it; its rows (the plan's, then one per evaluation picture).

    A plan the planner refuses (an InputError or PlanningError for this combination) gives
    one row with the reason in ``error`` and no cost: the task is done, not retried.
    """
    sc = _scenario(task.path)
    base = {'task': task.key, 'scenario': task.scenario, 'w': task.w, 'method': task.method,
            **dict(task.settings), 'plan': task.plan, 'sample': None}
    s = task.sampling
    airspace = sc.airspace or None
    t0 = time.perf_counter()
    try:
        cfg = task.config
        if task.plan == 'robust':
            result = plan_robust(sc.threats, sc.start, sc.goal, sc.box, cfg, s.robust_samples,
                                 Uncertainty(s.position_sigma_m, s.intensity_sigma),
                                 task.robust_seed, airspace=airspace)
        else:
            result = plan(sc.threats, sc.start, sc.goal, sc.box, cfg, airspace=airspace)
    except (InputError, PlanningError) as exc:
        return [{**base, 'J': None, 'J_L': None, 'J_R': None, 'J_planned': None,
                 'feasible': False, 'total_ms': 1e3 * (time.perf_counter() - t0),
                 'error': str(exc), 'path': None}]
    total_ms = 1e3 * (time.perf_counter() - t0)
    path = result.path
    nominal = result.cost if task.plan == 'nominal' else \
        picture_costs(path, [sc.threats], task.w, airspace)[0]
    feasible = bool(result.feasible)
    rows = [{**base, 'J': nominal.J, 'J_L': nominal.J_L, 'J_R': nominal.J_R,
             'J_planned': result.cost.J, 'feasible': feasible, 'total_ms': total_ms,
             'error': None, 'path': path.tolist()}]
    if s is not None:
        pictures = _evaluation(task.path, s.samples, s.position_sigma_m, s.intensity_sigma,
                               tuple(task.evaluation_seed))
        for i, c in enumerate(picture_costs(path, pictures, task.w, airspace)):
            rows.append({**base, 'sample': i, 'J': c.J, 'J_L': c.J_L, 'J_R': c.J_R,
                         'J_planned': None, 'feasible': feasible, 'total_ms': None,
                         'error': None, 'path': None})
    return rows
