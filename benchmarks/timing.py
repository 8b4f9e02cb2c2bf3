"""Timing, memory and report helpers shared by the benchmark scripts."""

from __future__ import annotations

import json
import resource
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


def matmul_gflops(size: int = 2048, repeat: int = 10) -> float:
    """The machine's pace now: GFLOP/s of a ``size``² float32 matrix product in torch, best
    of ``repeat`` (the figure docs/figures.md's timings quote). This machine's varies by the hour
    and, by a fifth, from one second to the next (144–185 in four calls): a rough gauge, which
    a benchmark comparing runs made one after another records before each."""
    import torch  # only the benchmarks that match or learn need it

    generator = torch.Generator().manual_seed(0)
    a, b = (torch.randn(size, size, generator=generator) for _ in range(2))
    torch.matmul(a, b)  # the first product allocates
    return 2 * size**3 / best_time(torch.matmul, a, b, repeat=repeat) / 1e9


def measure_peak(function, *args):
    """``function(*args)``'s result, wall time [s] and peak traced memory [MB]."""
    tracemalloc.start()
    start = time.perf_counter()
    result = function(*args)
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return result, seconds, peak / 2**20


def peak_rss_mb() -> float:
    """This process's peak resident memory so far [MB] (Linux reports it in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def print_report(report: dict, as_json: bool, number_format: str = "") -> None:
    """``report`` as JSON, or one ``name value`` line per figure (fractional numbers in
    ``number_format``, e.g. ``",.4g"``)."""
    if as_json:
        print(json.dumps(report, indent=1))
        return
    width = max(map(len, report)) + 2
    for key, value in report.items():
        shown = format(value, number_format) if isinstance(value, float) else value
        print(f"{key:{width}s} {shown}")
