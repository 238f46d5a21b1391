"""The one seam through which work is spread over processes: a ``concurrent.futures.Executor``.

:func:`open_executor` gives the local pool of spawned worker processes by default, or the
executor of a Dask distributed cluster (``Client.get_executor()``, extra ``psg-data[dask]``):

- ``scheduler=None``: :func:`psg_data._pool.process_pool`, ``workers`` spawned processes that stop
  at once on Ctrl-C or an error;
- ``scheduler="local"``: a ``LocalCluster`` of ``workers`` single-threaded worker processes on this
  machine, started and stopped with the executor;
- ``scheduler="tcp://HOST:PORT"``: the workers of a running cluster (``dask scheduler`` /
  ``dask worker``); they must import the same psg-data version and, for ``convert``, see the
  input and output paths (a shared filesystem).

The tasks submitted are plain picklable functions and their results are plain data, so the
numbers do not depend on the executor (tested byte for byte: tests/test_executors.py). Convert
(``psg_data.convert``) and the persistence harness (``psg_data.evaluation.evaluate_persistence``) use it;
a sweep over lab seeds or settings submits its runs the same way.
"""

from __future__ import annotations

import contextlib
import logging
import re
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from typing import Any

from psg_data.errors import PsgDataError

__all__ = ["open_executor", "check_scheduler", "SCHEDULER_HELP"]

log = logging.getLogger(__name__)

SCHEDULER_HELP = ("Run the worker tasks on Dask distributed (needs psg-data[dask]): 'local' starts a cluster of "
                  "--jobs workers on this machine, tcp://HOST:PORT uses a running scheduler. Default: local "
                  "worker processes.")
_ADDRESS = re.compile(r"(tcp|tls|ucx|inproc)://[^\s/]+(:\d+)?/?")


def check_scheduler(value: str | None) -> str | None:
    """``None``, ``"local"`` or a scheduler address, else PsgDataError naming what was expected."""
    if value is None or value == "local" or _ADDRESS.fullmatch(value):
        return value
    raise PsgDataError(f"--scheduler {value!r}: expected 'local' or a Dask scheduler address such as "
                       f"tcp://10.0.0.5:8786")


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise PsgDataError("--scheduler needs Dask distributed: pip install 'psg-data[dask]'") from None
    return distributed


@contextlib.contextmanager
def open_executor(workers: int, scheduler: str | None = None, *,
                  initializer: Callable[[], Any] | None = None) -> Iterator[Executor]:
    """An executor for the duration of a ``with`` block (see the module docstring).

    Args:
        workers: worker processes of the local pool or of a ``local`` cluster (ignored for an
            address: the cluster has the workers it has).
        scheduler: None, ``"local"`` or ``"tcp://HOST:PORT"``.
        initializer: called once in each worker process before its first task (the local pool's
            ``initializer``; a worker plugin on Dask).

    Raises:
        PsgDataError: a bad scheduler value, Dask not installed, or no scheduler at the address.
    """
    if scheduler is None:
        from psg_data._pool import process_pool

        with process_pool(max(1, workers), initializer) as pool:
            yield pool
        return
    check_scheduler(scheduler)
    distributed = _distributed()
    logging.getLogger("distributed").setLevel(logging.WARNING)  # not a line per worker start and stop
    cluster = None
    try:
        if scheduler == "local":
            cluster = distributed.LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                                               dashboard_address=":0", silence_logs=logging.ERROR)
            client = distributed.Client(cluster)
        else:
            client = distributed.Client(scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        raise PsgDataError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc})") from None
    log.info("running on Dask: %s", client.dashboard_link if cluster is None else f"local cluster, {workers} workers")
    try:
        if initializer is not None:
            client.register_plugin(_worker_plugin(distributed, initializer), name="psg-data-init")
        with client.get_executor(pure=False) as executor:
            yield executor
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _worker_plugin(distributed: Any, initializer: Callable[[], Any]) -> Any:
    """A Dask worker plugin running ``initializer`` once per worker (also on workers that join later)."""

    class _Init(distributed.WorkerPlugin):
        def __init__(self, fn: Callable[[], Any]) -> None:
            self.fn = fn

        def setup(self, worker: Any) -> None:
            self.fn()

    return _Init(initializer)
