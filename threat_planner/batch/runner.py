"""Run a study: check it, find what is missing in the results folder, run that, merge.

Everything is checked before the first plan (the study, every scenario, the folder); then
the tasks whose rows are not yet committed run on the chosen backend, chunk by chunk, each
finished chunk committed at once. At the end the rows are merged into ``results.parquet``
in task order and ``report.md`` is written.
"""

from __future__ import annotations

from contextlib import closing
from dataclasses import dataclass
import os
from pathlib import Path
import time
from typing import Callable

from threat_planner.batch.store import RESULTS, Store
from threat_planner.batch.study import load_study
from threat_planner.batch.tasks import chunks as make_chunks, task_list
from threat_planner.errors import InputError

__all__ = ['BatchRun', 'default_workers', 'run_batch']


@dataclass(frozen=True)
class BatchRun:
    """What one run did.

    Attributes
    ----------
    tasks : int
        Tasks of the study.
    ran : int
        Tasks run by this run (the others were committed before).
    rows : int
        Rows of ``results.parquet``.
    errors : int
        Tasks the planner refused (rows with an ``error``).
    seconds : float
        Wall time of the run [s].
    results : Path
        The table.
    report : Path
        The report.
    backend : str
        'local (N workers)' or 'ray (ADDRESS)'.

    """

    tasks: int
    ran: int
    rows: int
    errors: int
    seconds: float
    results: Path
    report: Path
    backend: str


def default_workers() -> int:
    """Return the number of CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def run_batch(study_path: str | Path, out: str | Path, workers: int | None = None,
              ray: str | None = None,
              progress: Callable[[int, int], None] | None = None) -> BatchRun:
    """Run the tasks of a study that ``out`` does not hold yet, then merge and report.

    Parameters
    ----------
    study_path : str or Path
        The study file.
    out : str or Path
        The results folder.
    workers : int, optional
        Local worker processes (default: the usable CPUs); with ``ray``, the CPUs of a
        local cluster started for the run.
    ray : str, optional
        Run on Ray: a cluster address or 'auto'; None runs locally.
    progress : callable, optional
        ``progress(done, total)`` after each chunk, over the tasks this run runs.

    Raises
    ------
    InputError
        A bad study, scenario, folder or option, before any plan runs.

    """
    t0 = time.perf_counter()
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise InputError(f'--workers: must be an integer >= 1, got {workers!r}')
    if ray is not None:
        from threat_planner.batch.cluster import import_ray
        import_ray()   # not installed: say how, before any work
        if not str(ray).strip():
            raise InputError("--ray: give a cluster address or 'auto'")
    study = load_study(study_path)
    _import_pyarrow()
    started = False
    if ray is not None:
        from threat_planner.batch.cluster import connect
        started = connect(ray, workers)
    try:
        store = Store(out, study)
    except InputError:
        if started:
            import ray as ray_module
            ray_module.shutdown()
        raise
    try:
        tasks = task_list(study)
        done = store.done()
        todo = [t for t in tasks if t.key not in done]
        if ray is not None:
            from threat_planner.batch.cluster import cluster_cpus
            n = cluster_cpus()   # the chunks are spread over the cluster's CPUs
        else:
            n = workers or default_workers()
        groups = make_chunks(todo, n)
        if ray is not None:
            from threat_planner.batch.cluster import run_ray
            finished = run_ray(groups, started)
            backend = f'ray ({ray})'
        else:
            from threat_planner.batch.local import run_local
            finished = run_local(groups, n)
            used = min(n, len(groups))
            backend = f'local ({used} worker{"" if used == 1 else "s"})' if used else 'local'
        count = 0
        if progress is not None and todo:
            progress(0, len(todo))
        # Closed on any way out (Ctrl-C above all): the backend then cancels the chunks not
        # started instead of running them all before the process may exit.
        with closing(finished):
            for rows in finished:
                store.commit(rows)
                count += len({r['task'] for r in rows})
                if progress is not None:
                    progress(count, len(todo))
        table = store.merge(tasks)
        from threat_planner.batch.report import write_report
        report = write_report(Path(out), table, study)
    finally:
        store.close()
    errors = len(set(table.filter(table.column('error').is_valid()).column('task')
                     .to_pylist()))
    return BatchRun(len(tasks), len(todo), table.num_rows, errors,
                    time.perf_counter() - t0, Path(out) / RESULTS, report, backend)


def _import_pyarrow() -> None:
    try:
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        raise InputError('batch: pyarrow is not installed; pip install pyarrow') from None
