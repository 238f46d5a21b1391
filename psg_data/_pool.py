"""Worker processes that stop at once on Ctrl-C or on an error (``--jobs`` in convert and psg-eval).

``concurrent.futures.ProcessPoolExecutor`` used as a context manager waits, on any exception, for
every queued task to run to the end (a Ctrl-C of ``psg-eval -j -1`` took 17-23 s), and each worker
gets the terminal's SIGINT too and prints its own traceback. Here the workers ignore SIGINT (the
parent handles it), and when the ``with`` body raises, queued tasks are cancelled and the workers
terminated before the exception goes on.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

__all__ = ["process_pool"]

_JOIN_S = 1.0


_MASKS = hasattr(signal, "pthread_sigmask")


def _init(initializer: Callable[..., Any] | None, initargs: tuple[Any, ...]) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a worker of ours: the parent stops it
    if _MASKS:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # started blocked (see _start_all)
    if initializer is not None:
        initializer(*initargs)


def _noop() -> None:
    return None


def _start_all(pool: ProcessPoolExecutor, n: int) -> None:
    """Start all ``n`` workers now, with SIGINT blocked: a started process inherits the mask, so a
    Ctrl-C while one is still importing cannot print its traceback (it ignores SIGINT once its
    initializer ran). The parent gets a Ctrl-C of that moment right after.
    """
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if _MASKS else None
    try:
        for _ in range(n):  # submitted before any finishes: each starts a worker
            pool.submit(_noop)
    finally:
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _stop(pool: ProcessPoolExecutor) -> None:
    procs = list((getattr(pool, "_processes", None) or {}).values())  # Python 3.14: pool.terminate_workers()
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(_JOIN_S)


@contextlib.contextmanager
def process_pool(max_workers: int, initializer: Callable[..., Any] | None = None,
                 initargs: tuple[Any, ...] = ()) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool; on leaving the block by an exception, workers are stopped at once.

    Args:
        max_workers: worker processes.
        initializer: run once in each worker (after SIGINT is set to be ignored there).
        initargs: arguments of ``initializer``.
    """
    pool = ProcessPoolExecutor(max_workers=max_workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init, initargs=(initializer, tuple(initargs)))
    try:
        _start_all(pool, max_workers)
        yield pool
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown(wait=True)
