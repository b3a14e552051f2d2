"""The Ray backend (``--ray ADDRESS|auto``): the same chunks as Ray tasks on a cluster.

Ray is an optional extra (``pip install 'threat_planner[cluster]'``). ``auto`` joins the
cluster in ``RAY_ADDRESS`` or, without one, starts a local cluster for the run; a process
that has already called ``ray.init`` keeps its connection. Ray runs a chunk again when the
worker running it dies (``max_retries``); the driver commits a chunk's rows only once, from
the attempt that returned, so a retried chunk adds no row twice. Every node must have
threat_planner installed (the tasks import it).
"""

from __future__ import annotations

import os
from typing import Iterator

from threat_planner.batch import worker
from threat_planner.batch.tasks import Task
from threat_planner.errors import InputError

__all__ = ['INSTALL_HINT', 'RETRIES', 'import_ray', 'run_ray']

INSTALL_HINT = ("--ray: Ray is not installed; install it with pip install "
                "'threat_planner[cluster]' (or pip install ray)")
#: Runs of a chunk after its worker died.
RETRIES = 3


def import_ray():
    """Return the ``ray`` module, or raise InputError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise InputError(INSTALL_HINT) from None
    return ray


def run_ray(chunks: list[list[Task]], address: str, workers: int | None
            ) -> Iterator[list[dict]]:
    """Run the chunks as Ray tasks; yield each chunk's rows as it finishes.

    Parameters
    ----------
    chunks : list of list of Task
        The work.
    address : str
        A cluster address, or 'auto'.
    workers : int, optional
        CPUs of a local cluster started here (None: all of this machine's).

    """
    ray = import_ray()
    started = False
    if not ray.is_initialized():
        kwargs = {'include_dashboard': False, 'log_to_driver': False}
        if address == 'auto' and not os.environ.get('RAY_ADDRESS'):
            kwargs['num_cpus'] = workers
        else:
            kwargs['address'] = None if address == 'auto' else address
        try:
            ray.init(**kwargs)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise InputError(f'--ray: cannot reach a Ray cluster at {address} '
                             f'({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})'
                             ) from None
        started = True
    remote = ray.remote(num_cpus=1, max_retries=RETRIES)(worker.run_chunk)
    pending = [remote.remote(c) for c in chunks]
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
