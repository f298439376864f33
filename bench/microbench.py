"""Timing helper of the benchmark scripts (``benchmarks/``): the median time of repeated calls."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def median_seconds(fn: Callable[[], object], repeat: int, warmup: int = 1,
                   clock: Callable[[], float] = time.perf_counter) -> float:
    """Median seconds of ``fn()`` over ``repeat`` calls after ``warmup`` untimed ones. ``clock``:
    ``time.perf_counter`` (wall) or ``time.process_time`` (process CPU time, for a shared machine)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t = clock()
        fn()
        times.append(clock() - t)
    return statistics.median(times)
