"""The default backend: worker processes on this machine that stay alive across chunks.

The workers fork from this process where that is safe (no other thread runs here and
numba's compute threads never started: the command line), so they start at once with the
planner imported; elsewhere (a caller that planned or runs threads) they fork from
multiprocessing's fork server, which imports the planner once. Each loads the compiled
kernels at its first plan and keeps them for every later chunk.
"""

from __future__ import annotations

from concurrent.futures import as_completed, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
import multiprocessing
import os
import sys
import threading
from typing import Iterator

from threat_planner.batch import worker
from threat_planner.batch.tasks import Task
from threat_planner.errors import PlanningError

__all__ = ['run_local', 'start_method']


def start_method() -> str:
    """Return 'fork' where forking this process is safe, else 'forkserver'."""
    if 'numba' not in sys.modules:
        launched = False  # the AOT kernels (serial): no threading layer to have launched
    else:
        try:
            from numba.np.ufunc import parallel
            launched = bool(getattr(parallel, '_is_initialized', True))
        except ImportError:  # pragma: no cover - numba is required
            launched = False
    # A fork copies locks held by other threads, and GNU OpenMP's pool (numba's threading
    # layer here) does not survive one.
    safe = threading.active_count() == 1 and not launched
    return 'fork' if safe and 'fork' in multiprocessing.get_all_start_methods() \
        else 'forkserver'


def run_local(chunks: list[list[Task]], workers: int) -> Iterator[list[dict]]:
    """Start ``workers`` processes on the chunks now; iterate over each chunk's rows.

    Raises
    ------
    PlanningError
        While iterating, if a worker process died (finished chunks stay committed).

    """
    if not chunks:
        return _finished(None, [])
    ctx = multiprocessing.get_context(start_method())
    if ctx.get_start_method() == 'forkserver':
        ctx.set_forkserver_preload(['threat_planner.batch.worker'])
    pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(chunks))), mp_context=ctx,
                               initializer=worker.initialise, initargs=(os.getpid(),))
    futures = [pool.submit(worker.run_chunk, c) for c in chunks]
    return _finished(pool, futures)


def _finished(pool: ProcessPoolExecutor | None, futures: list) -> Iterator[list[dict]]:
    try:
        for f in as_completed(futures):
            yield f.result()
    except BrokenProcessPool:
        raise PlanningError('batch: a worker process died (killed, or out of memory); the '
                            'finished tasks are kept: the same command runs the rest'
                            ) from None
    finally:
        # Cancelled here, not by shutdown(cancel_futures=True): the executor's manager
        # thread applies that only while the executor object lives, and it may be gone
        # by then (a Ctrl-C then ran every queued chunk before the process could exit).
        for f in futures:
            f.cancel()
        if pool is not None:
            pool.shutdown(wait=False)
