"""The estimator registry: built-ins by name (imported lazily) and plugins via entry points.

Third-party packages register an estimator factory (a class or callable taking keyword-only
settings) in the entry-point group ``psg_data.estimators``::

    [project.entry-points."psg_data.estimators"]
    my_estimator = "my_package.module:MyEstimator"

Plugins are listed by :func:`list_estimators` and imported only when selected by
:func:`get_estimator`.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from importlib import metadata
from typing import Any

from psg_data.errors import EstimatorError
from psg_data.estimators._base import PersistenceEstimator
from psg_data.estimators._params import check_params, declared

__all__ = ["get_estimator", "get_factory", "list_estimators", "register_estimator", "ENTRY_POINT_GROUP"]

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "psg_data.estimators"

_BUILTINS: dict[str, str] = {
    "perpetua_star": "psg_data.estimators._perpetua_star:PerpetuaStarEstimator",
    "perpetua_star_schedule": "psg_data.estimators._perpetua_star:PerpetuaStarScheduleEstimator",
    "perpetua_star_oracle": "psg_data.estimators._perpetua_star:PerpetuaStarOracleEstimator",
    "perpetua_star_annealed": "psg_data.estimators._perpetua_star:PerpetuaStarAnnealedEstimator",
    "perpetua": "psg_data.estimators._perpetua:PerpetuaEstimator",
    "persistence_filter": "psg_data.estimators._simple:PersistenceFilterEstimator",
    "fremen": "psg_data.estimators._fremen_estimator:FremenEstimator",
    "last_seen": "psg_data.estimators._simple:LastSeenEstimator",
    "always_present": "psg_data.estimators._simple:AlwaysPresentEstimator",
    "always_absent": "psg_data.estimators._simple:AlwaysAbsentEstimator",
    "time_of_week_frequency": "psg_data.estimators._simple:TimeOfWeekFrequencyEstimator",
    "training_mean": "psg_data.estimators._state_baselines:TrainingMeanEstimator",
    "time_of_day_histogram": "psg_data.estimators._state_baselines:TimeOfDayHistogramEstimator",
    "process_oracle": "psg_data.estimators._process_oracle:ProcessOracleEstimator",
}

_REGISTERED: dict[str, Callable[..., PersistenceEstimator]] = {}


def register_estimator(name: str, factory: Callable[..., PersistenceEstimator], *, overwrite: bool = False) -> None:
    """Register ``factory(**settings) -> estimator`` under ``name`` (for code that cannot ship an entry point)."""
    if not name or not isinstance(name, str):
        raise EstimatorError(f"estimator name must be a non-empty string, got {name!r}")
    if not overwrite and (name in _BUILTINS or name in _REGISTERED):
        raise EstimatorError(f"estimator {name!r} is already registered; pass overwrite=True to replace it")
    if not callable(factory):
        raise EstimatorError(f"estimator {name!r}: factory must be callable")
    _REGISTERED[name] = factory


def _entry_points() -> dict[str, metadata.EntryPoint]:
    eps = metadata.entry_points(group=ENTRY_POINT_GROUP)
    return {ep.name: ep for ep in eps}


def list_estimators() -> list[str]:
    """Names of all available estimators: built-in, registered and installed plugins (sorted)."""
    return sorted(set(_BUILTINS) | set(_REGISTERED) | set(_entry_points()))


def _load(spec: str) -> Callable[..., PersistenceEstimator]:
    mod, _, attr = spec.partition(":")
    return getattr(importlib.import_module(mod), attr)  # type: ignore[no-any-return]


def get_factory(name: str) -> Callable[..., PersistenceEstimator]:
    """The class or factory registered as ``name`` (not called; plugins are loaded here).

    Raises:
        EstimatorError: unknown name (the message lists the valid names) or a plugin that fails to load.
    """
    if name in _REGISTERED:
        return _REGISTERED[name]
    if name in _BUILTINS:
        return _load(_BUILTINS[name])
    eps = _entry_points()
    if name not in eps:
        raise EstimatorError(f"unknown estimator {name!r}; valid names: {', '.join(list_estimators())}")
    try:
        return eps[name].load()  # type: ignore[no-any-return]
    except Exception as exc:
        raise EstimatorError(f"estimator plugin {name!r} ({eps[name].value}) failed to load: {exc}") from exc


def get_estimator(name: str, **settings: Any) -> PersistenceEstimator:
    """An unfitted estimator configured with keyword-only ``settings``.

    Settings the estimator declares (``_parameters``) are checked here, before any data is read.

    Raises:
        EstimatorError: unknown name (the message lists the valid names) or invalid settings.
    """
    factory = get_factory(name)
    check_params(name, declared(factory), settings)
    try:
        est = factory(**settings)
    except TypeError as exc:
        raise EstimatorError(f"estimator {name!r}: invalid settings {sorted(settings)}: {exc}") from exc
    for attr in ("fit", "make_filter", "filter_from_state", "get_params"):
        if not callable(getattr(est, attr, None)):
            raise EstimatorError(f"estimator {name!r} does not implement PersistenceEstimator: missing {attr}()")
    return est
