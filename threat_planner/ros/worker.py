"""Plan workers: one plan at a time, the newest request waiting; optionally in a process."""

from __future__ import annotations

import threading
from typing import Callable, Optional

__all__ = ['PlanWorker', 'ProcessPlanWorker', 'prestart', 'WORKER_JOIN_S']

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


# -- planning in a child process -------------------------------------------------------

#: A running plan older than this is cancelled when a newer request waits [s]; a shorter
#: one finishes (so a flood of inputs still gets plans out, each for the newest state).
CANCEL_STALE_AFTER_S = 1.0
#: How often the waiting thread looks at stop, timeout and newer requests [s].
POLL_S = 0.02


#: A plan that has run this long starts the spare [s], or half its time limit if that is
#: shorter: only such a plan can be killed (a stale one after CANCEL_STALE_AFTER_S, at
#: its limit), and the spare's imports (~0.7 s) are done by then. A node whose plans are
#: shorter runs no spare (a process of numpy, scipy and the kernels less; the suite's
#: ~200 node starts each imported one after the first plan).
SPARE_AFTER_RUNNING_S = 0.3


def _child_main(conn, ready=None, go=None) -> None:
    """Plan requests from `conn` until it closes; send each phase back as it is ready.

    ``ready`` (a multiprocessing Event) is set once the kernels are loaded; they load once
    ``go`` is set (a child started before its node knows whether the cache is warm).
    """
    import signal
    import time

    # Ctrl-C reaches the whole process group; the parent decides when this child ends.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from threat_planner.ros.outputs import run_plan
    from threat_planner.core.compiled import ensure_compiled
    # run_plan imports the planner (scipy.spatial: a third of a second) only when called,
    # since the node's own process never plans: here it loads before the first request.
    import threat_planner.core.planner  # noqa: F401
    from threat_planner.bag.cdr import serialize_cdr
    if go is not None:
        # A cold cache is compiled by the node first; the child then loads what it wrote.
        go.wait()
    # Every kernel loaded now, while the child waits for its first request.
    ensure_compiled()
    if ready is not None:
        ready.set()

    def hand_over(phase, outcome) -> None:
        outcome.exception = None  # the text is in outcome.error; exceptions may not pickle
        if phase == 'done' and outcome.network is not None:
            # The markers go over as CDR bytes, published raw: unpickling the message
            # objects in the parent held its interpreter for 124 ms at 300 threats (and
            # publishing them cost another 60 ms of serialising); bytes take 0.1 ms.
            outcome.network = serialize_cdr(outcome.network)
        conn.send((phase, outcome))

    def early(outcome) -> None:
        conn.send(('initial', outcome))

    # The child's last plan, for a warm replan after a small change: a child replaced
    # after a cancel or a timeout starts cold, and plan_info says which (replay follows).
    previous = None
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            return
        conn.send(('started', None))
        warm = previous if request.settings.warm_replan else None
        outcome = run_plan(request, hand_over, time.time_ns, early=early, warm_start=warm)
        # A timed plan's static result (its path as planned, not as published) warms the next.
        previous = (outcome.static or outcome.result) if outcome.result is not None else previous
        conn.send(('end', None))


class _PlanProcess:
    """One spawned planning process and its pipe; killed to cancel what it plans.

    Parameters
    ----------
    held : bool
        The child imports, then waits for :meth:`release` before it loads the kernels.

    """

    def __init__(self, held: bool = False) -> None:
        import multiprocessing
        # spawn, not fork: the parent runs DDS threads whose locks a fork would copy.
        ctx = multiprocessing.get_context('spawn')
        self.conn, child = ctx.Pipe()
        self.ready = ctx.Event()
        self.go = ctx.Event()
        if not held:
            self.go.set()
        self.proc = ctx.Process(target=_child_main, args=(child, self.ready, self.go),
                                daemon=True, name='threat_planner_plan')
        self.proc.start()
        child.close()

    def release(self) -> None:
        """Let a held child load the kernels."""
        self.go.set()

    def kill(self) -> None:
        self.proc.kill()
        self.proc.join(1.0)
        self.conn.close()


#: The plan process :func:`prestart` began, until a :class:`ProcessPlanWorker` takes it.
_PRESTARTED: Optional[_PlanProcess] = None


def prestart() -> None:
    """Start the first plan process now, before this process imports rclpy and the core.

    A node's executable calls this first (:mod:`threat_planner.ros.entry`): the child's
    imports (~0.7 s) then run beside the node's own on a second core instead of after them.
    The child loads the kernels only when the node's worker takes it (the node compiles a
    cold cache first). A child never taken ends with this process (it is a daemon).
    """
    global _PRESTARTED
    if _PRESTARTED is None:
        _PRESTARTED = _PlanProcess(held=True)


def _first_process() -> _PlanProcess:
    """Return the prestarted plan process if it is alive, else a new one; released."""
    global _PRESTARTED
    child, _PRESTARTED = _PRESTARTED, None
    if child is not None and child.proc.exitcode is not None:
        child.kill()
        child = None
    child = child if child is not None else _PlanProcess()
    child.release()
    return child


class ProcessPlanWorker:
    """Plans in a child process, so a long plan never holds this process's interpreter.

    The executor keeps answering services and parameters while a plan runs; a plan is
    stopped by killing its process: on shutdown (at once), when it exceeds the request's
    ``settings.max_plan_time_s`` (a ``'timeout'`` phase with the network route as the
    best path so far when the search had finished, else an ``'error'`` phase), and when a newer
    request waits and the plan has run :data:`CANCEL_STALE_AFTER_S`, unless the previous
    plan was cancelled too (a ``'cancelled'`` phase; so some plan always finishes). A warm
    spare process takes over after a kill, so the next plan does not wait for the imports
    of a new one. The spare starts once a plan has run :data:`SPARE_AFTER_RUNNING_S` (or
    half its time limit), the first plan that could be killed; after a kill the next spare
    starts at once.

    Parameters
    ----------
    hand_over : Callable[[str, PlanOutcome], None]
        Called in the worker thread with each phase (``'paths'``, ``'done'``, ``'error'``,
        ``'timeout'``, ``'cancelled'``), as :func:`threat_planner.ros.outputs.run_plan`
        hands them over.
    name : str
        Thread name.

    """

    def __init__(self, hand_over: Callable[[str, object], None],
                 name: str = 'planner') -> None:
        self._hand_over = hand_over
        self._stopped = threading.Event()
        self._lock = threading.Lock()   # the child and the spare, swapped by two threads
        self._child = _first_process()
        self._spare: Optional[_PlanProcess] = None
        self._cancelled_last = False   # only the worker thread reads and writes it
        self._worker = PlanWorker(self._run, name=name)

    def _start_spare(self) -> None:
        with self._lock:
            if self._spare is None and not self._stopped.is_set():
                self._spare = _PlanProcess()

    def submit(self, job: object) -> bool:
        """Make `job` the next request (see :meth:`PlanWorker.submit`)."""
        return self._worker.submit(job)

    @property
    def busy(self) -> bool:
        """Whether a plan is running."""
        return self._worker.busy

    def stop(self, timeout: float = WORKER_JOIN_S) -> bool:
        """Kill the planning processes and end the thread; True if it ended in `timeout`."""
        self._stopped.set()
        ended = self._worker.stop(timeout)
        with self._lock:
            for child in (self._child, self._spare):
                if child is not None:
                    child.kill()
        return ended

    def _replace_child(self) -> None:
        with self._lock:
            self._child.kill()
            self._child = self._spare if self._spare is not None else _PlanProcess()
            self._spare = None if self._stopped.is_set() else _PlanProcess()

    def _run(self, request) -> None:
        import time

        from threat_planner.ros.outputs import PlanOutcome, timeout_outcome

        # The plan's clock starts when the child takes the request, not while a new child
        # still imports (seconds on a busy machine, which would time out a short limit).
        t0 = None
        limit = request.settings.max_plan_time_s
        best_so_far = None
        try:
            self._child.conn.send(request)
            while True:
                if self._stopped.is_set():
                    return
                if self._child.conn.poll(POLL_S):
                    phase, outcome = self._child.conn.recv()
                    if phase == 'end':
                        self._cancelled_last = False
                        return
                    if phase == 'started':
                        t0 = time.monotonic()
                        continue
                    if phase == 'initial':
                        best_so_far = outcome   # published only if the plan times out
                        continue
                    self._hand_over(phase, outcome)
                    continue
                if t0 is None:
                    continue
                running = time.monotonic() - t0
                if self._spare is None and running >= min(SPARE_AFTER_RUNNING_S, 0.5 * limit):
                    self._start_spare()
                if running > limit:
                    self._replace_child()
                    self._hand_over(*timeout_outcome(request, best_so_far, running, limit))
                    return
                # A stale plan gives way to the newer request, but never twice in a row:
                # inputs faster than plans would otherwise starve the outputs (no plan
                # ever finishing), so after a cancel the next plan always runs to its end.
                if (self._worker.has_pending and running >= CANCEL_STALE_AFTER_S
                        and not self._cancelled_last):
                    self._cancelled_last = True
                    self._replace_child()
                    self._hand_over('cancelled', PlanOutcome(request, plan_ms=1e3 * running))
                    return
        except (EOFError, OSError, BrokenPipeError) as exc:
            if self._stopped.is_set():
                return
            code = self._child.proc.exitcode
            self._replace_child()
            self._hand_over('error', PlanOutcome(
                request, error=f'planner process ended (exit code {code}): {exc}'))
