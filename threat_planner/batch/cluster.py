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
import socket
from typing import Iterator

from threat_planner.batch import worker
from threat_planner.batch.tasks import Task
from threat_planner.errors import InputError, PlanningError

__all__ = ['INSTALL_HINT', 'RETRIES', 'cluster_cpus', 'connect', 'import_ray', 'run_ray']

INSTALL_HINT = ("--ray: Ray is not installed; install it with pip install "
                "'threat_planner[cluster]' (or pip install ray)")
#: Runs of a chunk after its worker died.
RETRIES = 3
#: Longest wait for a cluster's address to answer [s].
CONNECT_S = 5.0


def import_ray():
    """Return the ``ray`` module, or raise InputError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise InputError(INSTALL_HINT) from None
    return ray


def connect(address: str, workers: int | None) -> bool:
    """Join the cluster at ``address`` (or start one for 'auto'); whether one was started.

    A process already connected (``ray.init`` called) keeps its connection.

    Parameters
    ----------
    address : str
        A cluster address (``host:port`` or ``ray://host:port``), or 'auto'.
    workers : int, optional
        CPUs of a local cluster started here (None: all of this machine's).

    Raises
    ------
    InputError
        Ray is not installed, or no cluster answers at the address.

    """
    ray = import_ray()
    if ray.is_initialized():
        return False
    kwargs = {'log_to_driver': False}
    target = address if address != 'auto' else os.environ.get('RAY_ADDRESS')
    if target:
        _check_reachable(target)
        kwargs['address'] = None if address == 'auto' else address
    else:
        kwargs.update(num_cpus=workers, include_dashboard=False)
    try:
        ray.init(**kwargs)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f'--ray: cannot join a Ray cluster at {target} ({first})') from None
    return True


def run_ray(chunks: list[list[Task]], started: bool) -> Iterator[list[dict]]:
    """Submit the chunks to the connected cluster now; iterate over each one's rows.

    ``started``: the cluster was started for this run (:func:`connect`), and is shut
    down after the last chunk.
    """
    ray = import_ray()
    remote = ray.remote(num_cpus=1, max_retries=RETRIES)(worker.run_chunk)
    pending = [remote.remote(c) for c in chunks]
    return _finished(ray, pending, started)


def _check_reachable(address: str) -> None:
    """Refuse at once an address where nothing listens (ray.init would retry for minutes)."""
    host, _, port = address.removeprefix('ray://').rpartition(':')
    try:
        with socket.create_connection((host or '127.0.0.1', int(port)), timeout=CONNECT_S):
            pass
    except ValueError:
        raise InputError(f"--ray: expected host:port or 'auto', got {address!r}") from None
    except OSError as exc:
        raise InputError(f'--ray: no Ray cluster answers at {address} '
                         f'({exc.strerror or type(exc).__name__})') from None


def cluster_cpus() -> int:
    """Return the CPUs of the connected cluster (at least 1)."""
    return max(1, int(import_ray().cluster_resources().get('CPU', 1)))


def _finished(ray, pending: list, started: bool) -> Iterator[list[dict]]:
    from ray.exceptions import NodeDiedError, WorkerCrashedError
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            try:
                yield ray.get(ready[0])
            except (WorkerCrashedError, NodeDiedError) as exc:
                raise PlanningError(f'batch --ray: a chunk\'s worker died {RETRIES + 1} '
                                    f'times ({type(exc).__name__}); the finished tasks are '
                                    'kept: the same command runs the rest') from None
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
