"""PlanWorker: one plan at a time in a daemon thread, the newest request waiting."""

from __future__ import annotations

import threading
from typing import Callable, Optional

__all__ = ['PlanWorker', 'WORKER_JOIN_S']

# A plan that cannot finish within this after shutdown is abandoned (the worker is a
# daemon thread): a 1000-threat 'best' plan takes tens of seconds and must not hold up
# SIGINT or SIGTERM. Its result would be dropped anyway, so waiting only lets an idle
# worker end; the node must exit within 1 s of the signal.
WORKER_JOIN_S = 0.1


class PlanWorker:
    """Runs one job at a time in a daemon thread, with a single latest-wins pending slot.

    Parameters
    ----------
    run : Callable[[object], None]
        Called in the worker thread with each job; must not raise.
    name : str
        Thread name.

    """

    def __init__(self, run: Callable[[object], None], name: str = 'planner') -> None:
        self._run = run
        self._cond = threading.Condition()
        self._pending: Optional[object] = None
        self._busy = False
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: object) -> bool:
        """Make `job` the next one to run.

        Parameters
        ----------
        job : object
            The job.

        Returns
        -------
        bool
            True if it replaced a pending job that had not started (that job is skipped).

        """
        with self._cond:
            if self._stopping:
                return False
            replaced = self._pending is not None
            self._pending = job
            self._cond.notify()
        return replaced

    @property
    def busy(self) -> bool:
        """Whether a job is running."""
        with self._cond:
            return self._busy

    @property
    def has_pending(self) -> bool:
        """Whether a job waits for the running one."""
        with self._cond:
            return self._pending is not None

    def stop(self, timeout: float = WORKER_JOIN_S) -> bool:
        """Drop the pending job and wait up to `timeout` s for the running one.

        Returns
        -------
        bool
            True if the thread ended within the timeout.

        """
        with self._cond:
            self._stopping = True
            self._pending = None
            self._cond.notify()
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
                job, self._pending = self._pending, None
                self._busy = True
            try:
                self._run(job)
            finally:
                with self._cond:
                    self._busy = False
