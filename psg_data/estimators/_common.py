"""Shared machinery of the built-in estimators: settings handling, filter time checks, per-edge fitting."""

from __future__ import annotations

import inspect
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError, NotFittedError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._params import Integral, Options, Param, Real, check_params
from psg_data.estimators._survival import SurvivalMixture
from psg_data.estimators._training import EdgeDurations, fit_lognormal_mixture

__all__ = ["BaseEstimator", "BaseFilter", "TRAINING_PARAMETERS", "edge_to_json", "edge_from_json", "fit_survivals", "streams_by_edge"]


def edge_to_json(edge: EdgeKey) -> list[str]:
    return [str(edge[0]), str(edge[1])]


def edge_from_json(v: Sequence[str]) -> EdgeKey:
    return (str(v[0]), str(v[1]))


_E = TypeVar("_E", bound="BaseEstimator")


def _same(a: Any, b: Any) -> bool:
    try:
        return bool(a == b) and type(a) is type(b)
    except Exception:  # arrays and other objects without a plain ==
        return a is b


def streams_by_edge(streams: Sequence[EdgeStream] | None) -> dict[EdgeKey, list[EdgeStream]]:
    out: dict[EdgeKey, list[EdgeStream]] = {}
    for s in streams or ():
        if not isinstance(s, EdgeStream):
            raise EstimatorError(f"fit: expected EdgeStream objects, got {type(s).__name__}")
        out.setdefault(s.edge, []).append(s)
    return out


class BaseEstimator:
    """scikit-learn style base: keyword-only settings stored unchanged, learned attributes end in ``_``.

    Subclasses declare their settings in ``_parameters`` (name -> :class:`~psg_data.estimators._params.Param`);
    :meth:`set_params` and :meth:`validate_params` check values against them, and ``psg-eval``
    parses command-line settings with them. ``sklearn.base.clone`` works on every subclass.
    """

    name: str = "base"
    _parameters: ClassVar[Mapping[str, Param]] = {}

    @classmethod
    def _param_names(cls) -> list[str]:
        for klass in cls.__mro__:
            init = klass.__dict__.get("__init__")
            if init is None:
                continue
            params = inspect.signature(init).parameters
            if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
                return [k for k in params if k != "self"]
        return []

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The keyword-only settings (``deep`` is accepted for scikit-learn; no setting is an estimator)."""
        return {k: getattr(self, k) for k in self._param_names()}

    def set_params(self: _E, **params: Any) -> _E:
        """Set settings by name (checked against the declarations); return self.

        Raises:
            EstimatorError: an unknown setting (the valid ones are listed) or a value out of range.
        """
        valid = self._param_names()
        for key, value in params.items():
            if key not in valid:
                raise EstimatorError(f"{self.name}: unknown setting {key!r}; valid settings: {', '.join(valid) or 'none'}")
            if key in self._parameters:
                self._parameters[key].check(self.name, key, value)
        for key, value in params.items():
            setattr(self, key, value)
        return self

    def validate_params(self) -> None:
        """Check every declared setting's current value; raise :class:`EstimatorError` on the first bad one."""
        check_params(self.name, self._parameters, self.get_params())

    def __repr__(self) -> str:
        """scikit-learn style: only the settings that differ from their defaults."""
        defaults = {}
        for klass in type(self).__mro__:
            init = klass.__dict__.get("__init__")
            if init is not None:
                for k, p in inspect.signature(init).parameters.items():
                    if p.default is not inspect.Parameter.empty:
                        defaults.setdefault(k, p.default)
        changed = {k: v for k, v in self.get_params().items() if k not in defaults or not _same(v, defaults[k])}
        args = ", ".join(f"{k}={v!r}" for k, v in changed.items())
        return f"{type(self).__name__}({args})"

    def _check_fitted(self) -> None:
        if not getattr(self, "fitted_", False):
            raise NotFittedError(f"{type(self).__name__} ({self.name}) is not fitted; call fit(train_streams) first")

    def _state_header(self, edge: EdgeKey) -> dict[str, Any]:
        return {"estimator": self.name, "edge": edge_to_json(edge)}

    def _check_state(self, state: dict[str, Any]) -> EdgeKey:
        self._check_fitted()
        if state.get("estimator") != self.name:
            raise EstimatorError(f"filter state is for estimator {state.get('estimator')!r}, not {self.name!r}")
        return edge_from_json(state["edge"])


class BaseFilter:
    """Time bookkeeping shared by the built-in filters.

    Subclasses implement ``_update_many(t, y)`` (validated, non-decreasing, >= last time) and
    ``_predict(t)`` (t already clamped to >= the last observation time), and ``_state()``.
    """

    def __init__(self, edge: EdgeKey) -> None:
        self.edge = edge
        self._last_t: float | None = None

    @property
    def last_t_s(self) -> float | None:
        return self._last_t

    def update(self, t_s: float, y: int) -> None:
        self.update_many(np.array([t_s], dtype=np.float64), np.array([y]))

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        yy = np.asarray(y).reshape(-1)
        if t.shape != yy.shape:
            raise EstimatorError(f"edge {self.edge}: update_many got {t.size} times and {yy.size} observations")
        if t.size == 0:
            return
        if not np.all(np.isfinite(t)):
            raise EstimatorError(f"edge {self.edge}: observation times must be finite")
        if not np.all((yy == 0) | (yy == 1)):
            raise EstimatorError(f"edge {self.edge}: observations must be 0 or 1")
        if t.size > 1 and np.any(np.diff(t) < 0):
            i = int(np.argmax(np.diff(t) < 0)) + 1
            raise EstimatorError(f"edge {self.edge}: observation times must be non-decreasing, got {t[i]} after {t[i - 1]}")
        if self._last_t is not None and t[0] < self._last_t:
            raise EstimatorError(f"edge {self.edge}: observation at t={t[0]} is earlier than the last one at t={self._last_t}")
        self._update_many(t, yy.astype(np.int8))
        self._last_t = float(t[-1])

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """P(present) at times ``t_s`` (any shape); times before the last observation are clamped to it."""
        t = np.asarray(t_s, dtype=np.float64)
        if not np.all(np.isfinite(t)):
            raise EstimatorError(f"edge {self.edge}: query times must be finite")
        if self._last_t is not None:
            t = np.maximum(t, self._last_t)
        out = np.asarray(self._predict(t.reshape(-1)), dtype=np.float64).reshape(t.shape)
        return np.clip(np.nan_to_num(out, nan=0.5), 0.0, 1.0)

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:  # pragma: no cover
        raise NotImplementedError

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover
        raise NotImplementedError


TRAINING_PARAMETERS: dict[str, Param] = {
    "max_components": Integral(1, 10, help="largest number of mixture components tried by AIC"),
    "p_m": Real(0.0, 0.5, none_ok=True, help="P(seen absent | present); none: estimated from the training data"),
    "p_f": Real(0.0, 0.5, none_ok=True, help="P(seen present | absent); none: estimated from the training data"),
    "durations": Options("segments", "ground_truth", "auto", help="where training run durations come from"),
    "min_segment": Integral(1, None, help="shortest change-point segment, observations"),
    "segment_penalty": Real(0.0, None, help="change-point penalty, nats"),
    "random_state": Integral(0, None, help="seed of the EM restarts"),
}
"""Settings shared by the estimators trained on run durations (Perpetua*, Perpetua)."""


def _fallback(d: NDArray[np.float64], pooled: NDArray[np.float64], dominant: bool, span_s: float,
              max_components: int, seed: int) -> SurvivalMixture:
    if d.size >= 2:
        return fit_lognormal_mixture(d, max_components=max_components, random_state=seed).mixture
    if dominant:  # the state (almost) never ended: long censored run
        return SurvivalMixture.lognormal_median(max(4.0 * span_s, 86400.0), 1.0)
    if pooled.size >= 2:
        return fit_lognormal_mixture(pooled, max_components=max_components, random_state=seed).mixture
    return SurvivalMixture.lognormal_median(3600.0, 1.0)


def fit_survivals(durs: dict[EdgeKey, EdgeDurations], *, max_components: int, seed: int) -> tuple[
        dict[EdgeKey, tuple[SurvivalMixture, SurvivalMixture]], tuple[SurvivalMixture, SurvivalMixture]]:
    """Per-edge (persistence, emergence) log-normal mixtures, plus pooled defaults for unseen edges."""
    pooled_p = np.concatenate([d.present for d in durs.values()] or [np.zeros(0)])
    pooled_a = np.concatenate([d.absent for d in durs.values()] or [np.zeros(0)])
    out = {}
    for e, d in durs.items():
        per = _fallback(d.present, pooled_p, d.mostly_present, d.span_s, max_components, seed)
        emg = _fallback(d.absent, pooled_a, not d.mostly_present, d.span_s, max_components, seed)
        out[e] = (per, emg)
    dper = (fit_lognormal_mixture(pooled_p, max_components=max_components, random_state=seed).mixture
            if pooled_p.size >= 2 else SurvivalMixture.lognormal_median(3600.0))
    demg = (fit_lognormal_mixture(pooled_a, max_components=max_components, random_state=seed).mixture
            if pooled_a.size >= 2 else SurvivalMixture.lognormal_median(3600.0))
    return out, (dper, demg)
