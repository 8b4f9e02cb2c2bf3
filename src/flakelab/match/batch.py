"""Many targets matched at once (``flakelab match --all``): the readings of a file shared out
over this process and worker processes.

:func:`~flakelab.match.search.match` runs on one thread (its batches are small, and a second
thread only adds contention), so a file of many readings leaves the other cores idle. Here
``jobs − 1`` worker processes are given the forward model once and take readings from the
front of the file while this process takes them from the back: a worker needs a few seconds
to start (the imports, the model, the compiled physics from numba's cache), and this process
matches meanwhile, so sharing out is never much slower than matching alone. Each result is
the reading's own, bit for bit, whichever process matched it (a match depends on its target
and ``settings.seed`` alone). Workers are started with ``spawn``, not ``fork``: a forked
copy of a process whose OpenMP threads already ran may hang.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import InvalidStateError, ProcessPoolExecutor
from multiprocessing import resource_tracker

from flakelab.errors import FlakelabError
from flakelab.match.search import MatchResult, match

__all__ = ["match_readings", "workers_for", "usable_cores"]

_worker: dict = {}


def usable_cores() -> int:
    """The cores this process may run on."""
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    return len(cores) if cores else os.cpu_count() or 1


def workers_for(readings: int, jobs: int | None = None) -> int:
    """How many processes match ``readings`` readings: ``jobs`` where given, else one for each
    core this process may use; never more than the readings, nor than the cores: a match
    keeps its core busy, so another process there matches no faster, and each takes about
    0.4 GB (``--jobs 40`` on two cores asked for 16 GB)."""
    if jobs is not None and jobs < 1:
        raise FlakelabError(f"--jobs: expected a whole number from 1, got {jobs}")
    cores = usable_cores()
    return max(1, min(jobs or cores, cores, readings))


def match_readings(
    readings: Sequence,
    forward,
    effect,
    *,
    jobs: int = 1,
    progress: Callable[[], None] | None = None,
    **keywords,
) -> list[MatchResult | FlakelabError]:
    """Each reading's :func:`~flakelab.match.search.match` (``keywords`` as it takes them), or
    the :class:`~flakelab.errors.FlakelabError` that refused it, in the readings' order,
    matched by ``jobs`` processes, this one among them; ``progress`` is called as each is
    done (from another thread for a worker's)."""
    results: list = [None] * len(readings)
    if jobs <= 1 or len(readings) <= 1:
        for i, reading in enumerate(readings):
            results[i] = _matched(reading, forward, effect, keywords)
            if progress:
                progress()
        return results
    with contextlib.ExitStack() as stack:
        with _stops_ignored():  # what the workers start with: their stop is this process's
            pool = stack.enter_context(
                ProcessPoolExecutor(
                    max_workers=jobs - 1,
                    mp_context=multiprocessing.get_context("spawn"),
                    initializer=_start_worker,
                    initargs=(forward, effect, keywords),
                )
            )
            futures = [pool.submit(_match_in_worker, reading) for reading in readings]
        if progress:
            for future in futures:
                future.add_done_callback(functools.partial(_matched_by_a_worker, progress))
        try:
            for i in reversed(range(len(readings))):  # a reading no worker took yet is ours
                if futures[i].cancel():
                    results[i] = _matched(readings[i], forward, effect, keywords)
                    if progress:
                        progress()
            for i, future in enumerate(futures):
                if not future.cancelled():
                    results[i] = future.result()
        except BaseException:  # a Ctrl-C or SIGTERM: the readings no worker began are dropped,
            _end_workers(pool)  # and those begun abandoned, not all matched before it stops
            raise
    return results


@contextlib.contextmanager
def _stops_ignored() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP ignored while the workers (and multiprocessing's resource
    tracker) are started, as they then keep ignoring them: a Ctrl-C, or a closed terminal,
    signals every process of the command. Each worker then printed a KeyboardInterrupt's
    traceback from wherever it was, and the tracker, ended by a SIGHUP, five more. This
    process stops the pool instead: the readings no worker began are dropped."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    stops = [s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s]
    handlers = {stop: signal.signal(stop, signal.SIG_IGN) for stop in stops}
    try:
        resource_tracker.ensure_running()
        yield
    finally:
        for stop, handler in handlers.items():
            signal.signal(stop, handler)


def _matched_by_a_worker(progress: Callable[[], None], future) -> None:
    """``progress`` called for a reading a worker matched, not for one cancelled or one whose
    worker was ended (:func:`_end_workers`): the bar then showed more done after the line that
    says the command stopped."""
    if not future.cancelled() and future.exception() is None:
        progress()


def _end_workers(pool: ProcessPoolExecutor) -> None:
    """The pool shut down without waiting, and each worker killed: it holds no file, and it
    ignores the stops (:func:`_stops_ignored`), so the readings it had begun kept a Ctrl-C
    waiting for seconds. Python 3.14 names this ``kill_workers``; before it, the workers are
    the pool's private ``_processes``, which a shutdown forgets."""
    if hasattr(pool, "kill_workers"):
        pool.kill_workers()
        return
    manager = getattr(pool, "_executor_manager_thread", None)
    workers = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    _hush_cancelled_futures(manager)
    for worker in workers:
        with contextlib.suppress(OSError):
            worker.kill()


def _hush_cancelled_futures(manager: threading.Thread | None) -> None:
    """Before Python 3.12 (gh-107219), the pool's manager thread, finding its workers ended,
    sets an exception on futures already cancelled, and its InvalidStateError printed a
    traceback after the line that says the command stopped."""
    previous = threading.excepthook

    def hook(args) -> None:
        if args.thread is manager and issubclass(args.exc_type, InvalidStateError):
            return
        previous(args)

    threading.excepthook = hook


def _matched(reading, forward, effect, keywords: dict) -> MatchResult | FlakelabError:
    try:
        return match(reading, forward, effect, **keywords)
    except FlakelabError as error:  # this reading's: the others go on
        return error


def _start_worker(forward, effect, keywords: dict) -> None:
    _worker.update(forward=forward, effect=effect, keywords=keywords)


def _match_in_worker(reading) -> MatchResult | FlakelabError:
    return _matched(reading, _worker["forward"], _worker["effect"], _worker["keywords"])
