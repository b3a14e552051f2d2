"""Wall times, background sampling, memory and the summary statistics of the suites."""

from __future__ import annotations

import os
from pathlib import Path
import statistics
import threading
import time
from typing import Callable, Optional, Sequence

import numpy as np


def timed(fn: Callable, *args, **kwargs) -> tuple[object, float]:
    """Call ``fn(*args, **kwargs)``; return its result and the wall time [ms]."""
    t0 = time.perf_counter()
    result = fn(*args, **kwargs)
    return result, 1e3 * (time.perf_counter() - t0)


def timed_median(repeats: int, fn: Callable, *args, **kwargs
                 ) -> tuple[object, float, list[float]]:
    """Call ``fn`` ``repeats`` times; the first result, the median and every wall time [ms]."""
    runs = [timed(fn, *args, **kwargs) for _ in range(max(repeats, 1))]
    times = [ms for _, ms in runs]
    return runs[0][0], statistics.median(times), times


def stats(values: Sequence[float]) -> dict[str, float]:
    """Return count, median, p95 and max of `values` (NaN for an empty sequence).

    Returns
    -------
    dict
        Keys ``n``, ``median``, ``p95``, ``max``.
    """
    if not len(values):
        return {'n': 0, 'median': float('nan'), 'p95': float('nan'), 'max': float('nan')}
    arr = np.asarray(values, dtype=float)
    return {'n': int(arr.size), 'median': float(np.median(arr)),
            'p95': float(np.percentile(arr, 95)), 'max': float(arr.max())}


def load_average() -> float:
    """Return the host's 1-minute load average (other jobs share the CPUs)."""
    return os.getloadavg()[0]


def rss_kib(pid: int) -> Optional[int]:
    """Return a process's resident set size ``VmRSS`` [KiB], or None if it is gone."""
    try:
        with open(f'/proc/{pid}/status') as status:
            for line in status:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def peak_rss_mb() -> float:
    """Return this process's peak resident set size [MiB].

    Reads ``VmHWM`` from ``/proc/self/status``: unlike ``ru_maxrss``, which Linux carries
    over from the parent through fork and exec, it covers only this process's own memory.
    Falls back to ``ru_maxrss`` where ``/proc`` is missing.
    """
    try:
        for line in Path('/proc/self/status').read_text().splitlines():
            if line.startswith('VmHWM:'):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def memory_summary(samples_kib: Sequence[int]) -> dict[str, float]:
    """Start, end, max and growth of RSS samples taken in time order [KiB].

    Returns
    -------
    dict
        ``start_mib``, ``end_mib``, ``max_mib``, ``growth_pct`` (end vs start) and
        ``max_growth_pct`` (max vs start).
    """
    start, end, peak = samples_kib[0], samples_kib[-1], max(samples_kib)
    return {'samples': len(samples_kib), 'start_mib': start / 1024, 'end_mib': end / 1024,
            'max_mib': peak / 1024, 'growth_pct': 100.0 * (end - start) / start,
            'max_growth_pct': 100.0 * (peak - start) / start}


class Sampler:
    """Calls a function every `period` s in a background thread and keeps the results.

    Parameters
    ----------
    fn : Callable[[], object]
        What to sample; its result is stored with the time (``time.monotonic()``).
    period : float
        Sampling period [s].
    """

    def __init__(self, fn: Callable[[], object], period: float = 1.0) -> None:
        self._fn = fn
        self._period = period
        self._stop = threading.Event()
        self.samples: list[tuple[float, object]] = []
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def start(self) -> 'Sampler':
        """Start sampling; returns self."""
        self._thread.start()
        return self

    def stop(self) -> list[tuple[float, object]]:
        """Stop sampling and return the samples."""
        self._stop.set()
        self._thread.join(10.0)
        return self.samples

    def values(self) -> list:
        """Return the sampled values, without their times, leaving out None."""
        return [v for _, v in list(self.samples) if v is not None]

    def _loop(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            self.samples.append((time.monotonic(), self._fn()))
            next_t += self._period
            self._stop.wait(max(0.0, next_t - time.monotonic()))
