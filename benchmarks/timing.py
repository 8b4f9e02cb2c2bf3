"""Timing and memory helpers shared by the benchmark scripts."""

from __future__ import annotations

import time
import tracemalloc


def best_time(function, *args, repeat: int = 3) -> float:
    """Shortest wall time [s] of ``repeat`` calls of ``function(*args)``."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        function(*args)
        best = min(best, time.perf_counter() - start)
    return best


def measure_peak(function, *args):
    """``function(*args)``'s result, wall time [s] and peak traced memory [MB]."""
    tracemalloc.start()
    start = time.perf_counter()
    result = function(*args)
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return result, seconds, peak / 2**20
