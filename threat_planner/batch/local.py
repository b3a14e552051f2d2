"""The default backend: worker processes on this machine that stay alive across chunks.

The processes fork from a server that has imported the planner once (multiprocessing's
``forkserver``: no fork of a parent that may run threads, and no import per worker); each
loads the compiled kernels at its first plan and keeps them for every later chunk.
"""

from __future__ import annotations

from concurrent.futures import as_completed, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
import multiprocessing
import os
from typing import Iterator

from threat_planner.batch import worker
from threat_planner.batch.tasks import Task
from threat_planner.errors import PlanningError

__all__ = ['run_local']


def run_local(chunks: list[list[Task]], workers: int) -> Iterator[list[dict]]:
    """Run the chunks on ``workers`` processes; yield each chunk's rows as it finishes.

    Raises
    ------
    PlanningError
        If a worker process died (the rows of finished chunks stay committed).

    """
    if not chunks:
        return
    ctx = multiprocessing.get_context('forkserver')
    ctx.set_forkserver_preload(['threat_planner.batch.worker'])
    pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(chunks))), mp_context=ctx,
                               initializer=worker.initialise, initargs=(os.getpid(),))
    futures = [pool.submit(worker.run_chunk, c) for c in chunks]
    try:
        for f in as_completed(futures):
            yield f.result()
    except BrokenProcessPool:
        raise PlanningError('batch: a worker process died (killed, or out of memory); the '
                            'finished tasks are kept: the same command runs the rest'
                            ) from None
    finally:
        pool.shutdown(wait=False, cancel_futures=True)
