"""Plugin isolation: every call into a plugin estimator goes through one guarded call.

A *plugin* is an estimator whose class is defined outside the ``psg_data`` package (an entry point
of the ``psg_data.estimators`` group, a class given to ``register_estimator`` or an object handed to
a task). Every task (persistence, navigation, doors, the simulation protocols) gets its estimators
through :func:`isolate`, which returns a built-in unchanged and wraps a plugin in a
:class:`GuardedEstimator`: its ``__init__`` (:func:`build`), ``get_params``, ``fit``,
``make_filter``, ``filter_from_state`` and its filters' ``update``, ``update_many``, ``predict`` and
``get_state`` run in :func:`guarded_call`, where

* any exception, and ``SystemExit`` (``sys.exit`` in plugin code), becomes a :class:`PluginError`
  naming the estimator and the call (``KeyboardInterrupt`` is left alone: Ctrl-C still stops the run);
* a call that runs longer than the time limit (:func:`estimator_timeout`, ``psg-eval
  --estimator-timeout``, default :data:`DEFAULT_TIMEOUT_S`) is interrupted and reported (a ``SIGALRM``
  watchdog; it works in the main thread of a process, which is where ``psg-eval`` and its worker
  processes run estimators; elsewhere, and on platforms without ``SIGALRM``, calls are not timed);
* arrays handed to the plugin (training streams, observations, query times) are read-only copies:
  a plugin that edits them in place fails in its own call and cannot change another estimator's data;
* ``make_filter`` must return a filter and ``predict`` one finite value in [0, 1] per time, checked
  before anything uses it (NaN or a value out of range is the plugin's error, not repaired).

Tasks catch :class:`PluginError` per estimator, report it and score the other estimators.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError, NotFittedError
from psg_data.schemas._streams import EdgeKey, EdgeStream

__all__ = ["PluginError", "GuardedEstimator", "GuardedFilter", "isolate", "is_plugin", "build", "guarded_call",
           "estimator_timeout", "estimator_timeout_set", "DEFAULT_TIMEOUT_S", "TIMEOUT_ENV"]

DEFAULT_TIMEOUT_S = 600.0
"""Default time limit of one plugin call (fit, predict, ...), seconds."""
TIMEOUT_ENV = "PSG_DATA_ESTIMATOR_TIMEOUT"
"""Environment variable holding the limit (seconds; 0 = none): worker processes inherit it."""

T = TypeVar("T")


class PluginError(EstimatorError):
    """A plugin estimator's call failed: it raised, exited, ran over the time limit or returned
    something invalid. ``estimator`` names it, ``stage`` the call (``fit``, ``predict``, ...);
    ``invalid`` is True when the call returned an invalid value (at time ``t_s``, for ``predict``).
    """

    def __init__(self, estimator: str, stage: str, detail: str, *, invalid: bool = False,
                 t_s: float | None = None) -> None:
        super().__init__(f"{stage} {detail}" + (f" at t_s={t_s!r}" if t_s is not None else ""))
        self.estimator, self.stage, self.detail, self.invalid, self.t_s = estimator, stage, detail, invalid, t_s

    def __reduce__(self) -> tuple[Any, ...]:  # picklable across worker processes
        return _plugin_error, (self.estimator, self.stage, self.detail, self.invalid, self.t_s)

    def record(self, label: str | None = None) -> dict[str, Any]:
        """The failure as an entry of ``results.json`` ``errors`` (estimator, stage, message)."""
        who = label or self.estimator
        return {"estimator": who, "stage": self.stage, "message": f"estimator {who!r}: {self}"}


def _plugin_error(estimator: str, stage: str, detail: str, invalid: bool, t_s: float | None) -> PluginError:
    return PluginError(estimator, stage, detail, invalid=invalid, t_s=t_s)


class _Timeout(BaseException):
    """Raised into a plugin call by the watchdog (a BaseException: ``except Exception`` does not hide it)."""


def estimator_timeout() -> float | None:
    """The time limit of one plugin call in seconds (None: no limit): ``$PSG_DATA_ESTIMATOR_TIMEOUT``
    or :data:`DEFAULT_TIMEOUT_S`.
    """
    text = os.environ.get(TIMEOUT_ENV, "")
    try:
        value = float(text) if text.strip() else DEFAULT_TIMEOUT_S
    except ValueError:
        value = DEFAULT_TIMEOUT_S
    return value if value > 0 and math.isfinite(value) else None


@contextlib.contextmanager
def estimator_timeout_set(seconds: float | None) -> Iterator[None]:
    """Within the block, plugin calls are limited to ``seconds`` (None or 0: no limit); worker
    processes started inside it inherit the limit (through :data:`TIMEOUT_ENV`).
    """
    old = os.environ.get(TIMEOUT_ENV)
    os.environ[TIMEOUT_ENV] = repr(float(seconds or 0.0))
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(TIMEOUT_ENV, None)
        else:
            os.environ[TIMEOUT_ENV] = old


class _Watchdog:
    """``SIGALRM`` after ``seconds`` raises :class:`_Timeout` in the main thread (no-op where unavailable)."""

    def __init__(self, seconds: float | None) -> None:
        self.seconds, self.armed = seconds, False
        self.old: Any = None

    def _fire(self, signum: int, frame: Any) -> None:
        if self.armed:
            self.armed = False
            raise _Timeout

    def __enter__(self) -> _Watchdog:
        usable = (self.seconds is not None and hasattr(signal, "setitimer")
                  and threading.current_thread() is threading.main_thread()
                  and signal.getitimer(signal.ITIMER_REAL)[0] == 0)  # someone else's alarm runs: leave it
        if usable:
            self.old = signal.signal(signal.SIGALRM, self._fire)
            self.armed = True
            signal.setitimer(signal.ITIMER_REAL, float(self.seconds))  # type: ignore[arg-type]
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.old is not None:
            self.armed = False
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self.old)


class _Health:
    """Shared by a guarded estimator and its filters (copies included): once a call ran over the time
    limit, later calls fail at once instead of each waiting out the limit again.
    """

    def __init__(self) -> None:
        self.timed_out: str | None = None

    def __deepcopy__(self, memo: dict[int, Any]) -> _Health:
        return self


def guarded_call(estimator: str, stage: str, fn: Callable[..., T], *args: Any,
                 passthrough: tuple[type[BaseException], ...] = (), health: _Health | None = None,
                 **kwargs: Any) -> T:
    """``fn(*args, **kwargs)`` for plugin ``estimator``; its failure (an exception, ``SystemExit``,
    running over :func:`estimator_timeout`) becomes a :class:`PluginError` naming ``stage``.

    Exceptions of the types in ``passthrough`` (e.g. ``NotFittedError``, part of the contract) and
    ``KeyboardInterrupt`` are raised unchanged. With ``health``, a call after one that ran over the
    limit is not made (PluginError at once).
    """
    if health is not None and health.timed_out is not None:
        raise PluginError(estimator, stage, f"not called: {health.timed_out}")
    limit = estimator_timeout()
    try:
        with _Watchdog(limit):
            return fn(*args, **kwargs)
    except _Timeout:
        err = PluginError(estimator, stage, f"took longer than the time limit of {limit:g} s "
                                            "(psg-eval --estimator-timeout)")
        if health is not None:
            health.timed_out = f"its {stage} took longer than the time limit of {limit:g} s"
        raise err from None
    except PluginError:
        raise
    except passthrough:
        raise
    except SystemExit as e:
        raise PluginError(estimator, stage, f"called sys.exit({e.code!r})") from None
    except Exception as e:  # noqa: BLE001 - whatever the plugin raises is its failure
        text = " ".join(str(e).split())[:500]
        raise PluginError(estimator, stage, f"raised {type(e).__name__}: {text}") from None


def is_plugin(estimator: Any) -> bool:
    """Whether ``estimator``'s class is defined outside the ``psg_data`` package."""
    module = str(getattr(type(estimator), "__module__", ""))
    return not (module == "psg_data" or module.startswith("psg_data."))


def build(name: str, factory: Callable[..., T], **kwargs: Any) -> Any:
    """``isolate(factory(**kwargs), name)``, the construction guarded (a raising ``__init__`` is a PluginError)."""
    return isolate(guarded_call(name, "__init__", factory, **kwargs), name)


def isolate(estimator: Any, name: str | None = None) -> Any:
    """A built-in estimator unchanged; a plugin wrapped in a :class:`GuardedEstimator` (once)."""
    if isinstance(estimator, GuardedEstimator) or not is_plugin(estimator):
        return estimator
    return GuardedEstimator(estimator, name or str(getattr(estimator, "name", type(estimator).__name__)))


def _frozen(a: ArrayLike, dtype: Any = None) -> NDArray[Any]:
    out = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def _frozen_streams(streams: Sequence[EdgeStream] | None) -> list[EdgeStream] | None:
    """Read-only copies of the streams (their meta dicts copied)."""
    if streams is None:
        return None
    out: list[EdgeStream] = []
    for s in streams:
        if isinstance(s, EdgeStream):
            s = EdgeStream(s.edge, s.t_s, s.y, dict(s.meta))  # its own copies of the arrays
            s.t_s.setflags(write=False)
            s.y.setflags(write=False)
        out.append(s)
    return out


class _Forwarding:
    """Attributes not defined here are read from the wrapped plugin object (``_inner``)."""

    _inner: Any
    _name: str
    _health: _Health

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") or attr in ("_inner", "_name", "_health"):
            raise AttributeError(attr)
        return getattr(self._inner, attr)

    def _call(self, stage: str, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        return guarded_call(self._name, stage, fn, *args, health=self._health, **kwargs)


class GuardedFilter(_Forwarding):
    """A plugin's :class:`~psg_data.estimators.EdgeFilter` whose every call is guarded and checked."""

    def __init__(self, inner: Any, name: str, health: _Health | None = None) -> None:
        self._inner, self._name, self._health = inner, name, health or _Health()

    @property
    def last_t_s(self) -> float | None:
        """The plugin filter's ``last_t_s``."""
        return self._call("last_t_s", lambda: self._inner.last_t_s)

    def update(self, t_s: float, y: int) -> None:
        """The plugin's ``update`` (guarded)."""
        self._call("update", self._inner.update, float(t_s), int(y))

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        """The plugin's ``update_many`` on read-only copies (guarded)."""
        self._call("update_many", self._inner.update_many, _frozen(t_s), _frozen(y))

    def start(self, t_s: float) -> None:
        """The plugin's ``start`` if it has one (guarded)."""
        if hasattr(self._inner, "start"):
            self._call("start", self._inner.start, float(t_s))

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """The plugin's ``predict`` on a read-only copy, checked: one finite value in [0, 1] per time."""
        t = _frozen(t_s, np.float64)

        def call() -> NDArray[np.float64]:
            return np.array(self._inner.predict(t), dtype=np.float64)

        p = self._call("predict", call)
        if p.shape != t.shape:
            if p.size != t.size:
                raise PluginError(self._name, "predict", f"returned {p.size} values for {t.size} times", invalid=True)
            p = p.reshape(t.shape)
        bad = ~np.isfinite(p) | (p < 0.0) | (p > 1.0)
        if np.any(bad):
            i = int(np.argmax(bad.reshape(-1)))
            v = float(p.reshape(-1)[i])
            kind = "NaN" if math.isnan(v) else f"{v!r} outside [0, 1]"
            raise PluginError(self._name, "predict", f"returned {kind} ({int(bad.sum())} of {p.size} values invalid)",
                              invalid=True, t_s=float(t.reshape(-1)[i]))
        return p

    def get_state(self) -> dict[str, Any]:
        """The plugin's ``get_state`` (guarded)."""
        state = self._call("get_state", self._inner.get_state)
        if not isinstance(state, dict):
            raise PluginError(self._name, "get_state", f"returned {type(state).__name__}, not a dict")
        return state


_FILTER_MEMBERS = ("update", "update_many", "predict", "get_state")


class GuardedEstimator(_Forwarding):
    """A plugin :class:`~psg_data.estimators.PersistenceEstimator` whose every call is guarded; its
    filters are :class:`GuardedFilter`. Other attributes are read from the plugin.
    """

    def __init__(self, inner: Any, name: str, health: _Health | None = None) -> None:
        self._inner, self._name, self._health = inner, name, health or _Health()

    @property
    def plugin(self) -> Any:
        """The wrapped plugin estimator."""
        return self._inner

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The plugin's ``get_params`` (guarded; it must return a dict)."""
        def call() -> Any:
            try:
                return self._inner.get_params(deep=deep)
            except TypeError:  # a plugin whose get_params takes no ``deep``
                return self._inner.get_params()

        params = self._call("get_params", call)
        if not isinstance(params, dict):
            raise PluginError(self._name, "get_params", f"returned {type(params).__name__}, not a dict")
        return params

    def fresh(self) -> GuardedEstimator:
        """An unfitted copy with the same settings (guarded)."""
        params = self.get_params(deep=False)
        return GuardedEstimator(self._call("__init__", type(self._inner), **params), self._name, self._health)

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC", **kwargs: Any) -> GuardedEstimator:
        """The plugin's ``fit`` on read-only copies of the streams (guarded); returns self."""
        kw = {"val_streams": _frozen_streams(val_streams)} if val_streams is not None else {}
        self._call("fit", self._inner.fit, _frozen_streams(streams), timezone=timezone, **kw, **kwargs)
        return self

    def _filter(self, f: Any, stage: str) -> GuardedFilter:
        missing = [m for m in _FILTER_MEMBERS if not callable(getattr(f, m, None))]
        if missing:
            raise PluginError(self._name, stage, f"returned {type(f).__name__}, not a filter (no "
                                                 f"{', '.join(m + '()' for m in missing)})")
        return GuardedFilter(f, self._name, self._health)

    def make_filter(self, edge: EdgeKey) -> GuardedFilter:
        """The plugin's ``make_filter`` (guarded; NotFittedError passes), its filter guarded."""
        f = self._call("make_filter", self._inner.make_filter, edge, passthrough=(NotFittedError,))
        return self._filter(f, "make_filter")

    def filter_from_state(self, state: dict[str, Any]) -> GuardedFilter:
        """The plugin's ``filter_from_state`` (guarded; NotFittedError passes), its filter guarded."""
        f = self._call("filter_from_state", self._inner.filter_from_state, state,
                         passthrough=(NotFittedError,))
        return self._filter(f, "filter_from_state")
