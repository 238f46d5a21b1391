"""Shared machinery of the built-in estimators: settings handling, filter time checks, per-edge fitting."""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError, NotFittedError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._survival import SurvivalMixture
from psg_data.estimators._training import EdgeDurations, fit_lognormal_mixture

__all__ = ["BaseEstimator", "BaseFilter", "edge_to_json", "edge_from_json", "fit_survivals", "streams_by_edge"]


def edge_to_json(edge: EdgeKey) -> list[str]:
    return [str(edge[0]), str(edge[1])]


def edge_from_json(v: Sequence[str]) -> EdgeKey:
    return (str(v[0]), str(v[1]))


def streams_by_edge(streams: Sequence[EdgeStream] | None) -> dict[EdgeKey, list[EdgeStream]]:
    out: dict[EdgeKey, list[EdgeStream]] = {}
    for s in streams or ():
        if not isinstance(s, EdgeStream):
            raise EstimatorError(f"fit: expected EdgeStream objects, got {type(s).__name__}")
        out.setdefault(s.edge, []).append(s)
    return out


class BaseEstimator:
    """scikit-learn style base: keyword-only settings stored unchanged, learned attributes end in ``_``."""

    name: str = "base"

    def get_params(self) -> dict[str, Any]:
        for cls in type(self).__mro__:
            init = cls.__dict__.get("__init__")
            if init is None:
                continue
            params = inspect.signature(init).parameters
            if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
                return {k: getattr(self, k) for k in params if k != "self"}
        return {}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
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
