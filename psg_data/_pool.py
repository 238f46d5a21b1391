"""Worker processes that stop at once on Ctrl-C or on an error (``--jobs`` in convert and psg-eval).

``concurrent.futures.ProcessPoolExecutor`` used as a context manager waits, on any exception, for
every queued task to run to the end (a Ctrl-C of ``psg-eval -j -1`` took 17-23 s), and each worker
gets the terminal's SIGINT too and prints its own traceback. Here the workers ignore SIGINT (the
parent handles it), and when the ``with`` body raises, queued tasks are cancelled and the workers
terminated before the exception goes on; a worker whose parent is killed (SIGTERM, SIGHUP of a
closed terminal, SIGKILL) ends by itself within a second instead of finishing its task for nobody.
Multiprocessing's resource tracker (a process started with
the first pool, which otherwise ends only after the command has exited, left behind in its process
group) is stopped and reaped at exit, after the queues' semaphores are released.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

__all__ = ["process_pool"]

_JOIN_S = 1.0
_PARENT_POLL_S = 0.5
"""How often a worker looks whether its parent is still there (seconds)."""


_MASKS = hasattr(signal, "pthread_sigmask")


def _watch_parent(parent: int) -> None:
    """End this worker once its parent is gone (killed by SIGTERM, SIGHUP or SIGKILL, it cannot stop us).

    Polling ``os.getppid()`` works on every platform (a worker re-parented to init, or to a subreaper,
    sees another pid); ``prctl(PR_SET_PDEATHSIG)`` would be Linux only and fires on the death of the
    parent's *thread*. ``os._exit``: no cleanup of a task that has no one to report to.
    """
    while os.getppid() == parent:
        time.sleep(_PARENT_POLL_S)
    os._exit(1)


def _init(initializer: Callable[..., Any] | None, initargs: tuple[Any, ...], parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a worker of ours: the parent stops it
    threading.Thread(target=_watch_parent, args=(parent,), name="psg-data-parent-watch", daemon=True).start()
    if _MASKS:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # started blocked (see _start_all)
    if initializer is not None:
        initializer(*initargs)


def _noop() -> None:
    return None


def _stop_resource_tracker() -> None:
    from multiprocessing import resource_tracker

    stop = getattr(resource_tracker._resource_tracker, "_stop", None)  # Python >= 3.8 (private)
    if stop is not None:
        stop()


_TRACKER_STOP: list[Any] = []


def _stop_tracker_at_exit() -> None:
    """Stop and reap the resource tracker when the command exits, after multiprocessing's finalizers.

    A finalizer of negative priority runs in multiprocessing's exit handler after those of priority
    0 (the semaphores' unlink and unregister, which need the tracker) and after the children are
    joined; without it the tracker exits only once the parent is gone and is left to the init process.
    """
    if not _TRACKER_STOP:
        from multiprocessing import util

        _TRACKER_STOP.append(util.Finalize(None, _stop_resource_tracker, exitpriority=-100))


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
    _stop_tracker_at_exit()
    pool = ProcessPoolExecutor(max_workers=max_workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init, initargs=(initializer, tuple(initargs), os.getpid()))
    try:
        _start_all(pool, max_workers)
        yield pool
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown(wait=True)
