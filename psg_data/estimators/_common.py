"""Shared machinery of the built-in estimators: settings handling, filter time checks, per-edge fitting."""

from __future__ import annotations

import inspect
import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError, NotFittedError
from psg_data.estimators._base import EdgeKey, EdgeStream, streams_by_edge
from psg_data.estimators._interval_em import INTERVAL_FAMILIES
from psg_data.estimators._mixture import ESCAPE_FIRST
from psg_data.estimators._params import Integral, Options, Param, Real, check_params
from psg_data.estimators._survival_training import SEGMENTATIONS, fit_edge_survivals, training_runs

__all__ = ["BaseEstimator", "BaseFilter", "STATE_KEYS", "TRAINING_PARAMETERS", "edge_to_json", "edge_from_json",
           "fit_training", "streams_by_edge", "escape_floors", "log_fit_summary"]

log = logging.getLogger(__name__)


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


class BaseEstimator:
    """scikit-learn style base of an estimator: keyword-only settings stored unchanged, learned
    attributes end in ``_``.

    A subclass sets ``name``, takes its settings as keyword-only ``__init__`` arguments stored under
    the same names, and implements ``fit`` (set ``self.fitted_ = True``, return self),
    ``make_filter(edge)`` (call :meth:`check_fitted` first) and ``filter_from_state(state)``
    (:meth:`edge_of_state` checks the state and returns its edge; a :class:`BaseFilter` then takes
    its time back with :meth:`BaseFilter.restore_state`).

    Subclasses declare their settings in ``_parameters`` (name -> :class:`~psg_data.estimators._params.Param`);
    :meth:`set_params` and :meth:`validate_params` check values against them, and ``psg-eval``
    parses command-line settings with them. ``sklearn.base.clone`` works on every subclass.
    """

    name: str = "base"
    _parameters: ClassVar[Mapping[str, Param]] = {}

    @property
    def fit_depends_on_seed(self) -> bool:
        """Whether :meth:`fit` can give another model for another ``random_state``.

        True when the estimator has a ``random_state`` setting (e.g. EM restarts); a subclass
        overrides it to declare otherwise. ``psg-eval`` fits an estimator once when this is False,
        whatever ``--seeds`` says (its seeds would repeat the same run).
        """
        return "random_state" in self._param_names()

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
                raise EstimatorError(f"{self.name}: unknown setting {key!r}; valid settings: "
                                     f"{', '.join(valid) or 'none'}")
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
        defaults: dict[str, Any] = {}
        for klass in type(self).__mro__:
            init = klass.__dict__.get("__init__")
            if init is not None:
                for k, p in inspect.signature(init).parameters.items():
                    if p.default is not inspect.Parameter.empty:
                        defaults.setdefault(k, p.default)
        changed = {k: v for k, v in self.get_params().items() if k not in defaults or not _same(v, defaults[k])}
        args = ", ".join(f"{k}={v!r}" for k, v in changed.items())
        return f"{type(self).__name__}({args})"

    def check_fitted(self) -> None:
        """Raise :class:`~psg_data.errors.NotFittedError` unless :meth:`fit` has run (``fitted_`` is set):
        the first line of a plugin's ``make_filter``.
        """
        if not getattr(self, "fitted_", False):
            raise NotFittedError(f"{type(self).__name__} ({self.name}) is not fitted; call fit(train_streams) first")

    def edge_of_state(self, state: Mapping[str, Any]) -> EdgeKey:
        """The edge of a filter state (:data:`STATE_KEYS`), checked to be this estimator's: the first line
        of a plugin's ``filter_from_state``. No fit is required: a built-in filter's state holds what it
        learned (a saved PredictiveGraph is loaded onto a fresh estimator).

        Raises:
            EstimatorError: the state is another estimator's, or has no edge.
        """
        if state.get("estimator") != self.name:
            raise EstimatorError(f"filter state is for estimator {state.get('estimator')!r}, not {self.name!r}")
        if "edge" not in state:
            raise EstimatorError(f"filter state of {self.name!r}: no 'edge' key; expected [object_id, receptacle_id]")
        return edge_from_json(state["edge"])

    _check_fitted = check_fitted  # the former private names (plugins written before the public hooks)
    _check_state = edge_of_state


STATE_KEYS: dict[str, str] = {
    "estimator": "the estimator's registry name (``filter_from_state`` refuses another's state)",
    "edge": "[object_id, receptacle_id]",
    "last_t_s": "time (Unix s) of the last observation applied, or null before the first",
}
"""The keys every filter state (``EdgeFilter.get_state()``) has, and what they hold; a filter adds its own
(what it learned and its running belief). :meth:`BaseFilter.base_state` writes them,
:meth:`BaseEstimator.edge_of_state` and :meth:`BaseFilter.restore_state` read them back."""


class BaseFilter:
    """Time bookkeeping shared by the built-in filters (an :class:`~psg_data.estimators.EdgeFilter`).

    Subclasses implement ``_update_many(t, y)`` (observations already validated: finite times in
    seconds, non-decreasing and not before the last one, values 0/1 as int8), ``_predict(t)`` (a
    1-D array of times already clamped to >= :attr:`last_t_s`; return P(present) in [0, 1]: a
    built-in's NaN is read as 0.5 and values are clipped; a plugin's values are returned unrepaired,
    and the tasks report NaN or a value out of range as its error) and ``get_state()`` (a
    JSON-serialisable dict: :meth:`base_state` plus the filter's own keys; the estimator's
    ``filter_from_state`` rebuilds the filter and calls :meth:`restore_state`).
    """

    _repairs_predictions: ClassVar[bool] = True
    """Built-in filters read a NaN of ``_predict`` as 0.5 and clip to [0, 1]; a plugin's (a subclass
    defined outside psg_data) values are not repaired (psg_data.estimators._guard checks them)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls._repairs_predictions = cls.__module__ == "psg_data" or cls.__module__.startswith("psg_data.")

    def __init__(self, edge: EdgeKey) -> None:
        self.edge = edge
        self._last_t: float | None = None

    @property
    def last_t_s(self) -> float | None:
        """Time (s) of the last observation applied, None before the first."""
        return self._last_t

    def base_state(self, estimator: str) -> dict[str, Any]:
        """The keys of :data:`STATE_KEYS` for this filter of ``estimator`` (its registry name): the start
        of a ``get_state()``.
        """
        return {"estimator": estimator, "edge": list(self.edge), "last_t_s": self._last_t}

    def restore_state(self, state: Mapping[str, Any]) -> None:
        """Take back the time of a state (``last_t_s``) into a filter rebuilt by ``filter_from_state``.

        Raises:
            EstimatorError: ``last_t_s`` is neither null nor a finite number.
        """
        t = state.get("last_t_s")
        if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t)):
            raise EstimatorError(f"edge {self.edge}: filter state last_t_s {t!r}: expected a finite time in s or null")
        self._last_t = None if t is None else float(t)

    def update(self, t_s: float, y: int) -> None:
        """Apply one observation ``y`` (1 seen present, 0 seen absent) at ``t_s`` (s)."""
        self.update_many(np.array([t_s], dtype=np.float64), np.array([y]))

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        """Apply observations in time order (checked: equal lengths, finite times, 0/1 values,
        non-decreasing and not before the last one; else :class:`EstimatorError`).
        """
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        yy = np.asarray(y).reshape(-1)
        if t.shape != yy.shape:
            raise EstimatorError(f"edge {self.edge}: update_many got {t.size} times and {yy.size} observations")
        if t.size == 0:
            return
        if not np.isfinite(t).all():  # the arrays' own all()/any(): np.all's dispatch cost per observation
            raise EstimatorError(f"edge {self.edge}: observation times must be finite")
        if not ((yy == 0) | (yy == 1)).all():
            raise EstimatorError(f"edge {self.edge}: observations must be 0 or 1")
        if t.size > 1 and (np.diff(t) < 0).any():
            i = int(np.argmax(np.diff(t) < 0)) + 1
            raise EstimatorError(f"edge {self.edge}: observation times must be non-decreasing, got {t[i]} after "
                                 f"{t[i - 1]}")
        if self._last_t is not None and t[0] < self._last_t:
            raise EstimatorError(f"edge {self.edge}: observation at t={t[0]} is earlier than the last one at "
                                 f"t={self._last_t}")
        self._update_many(t, yy.astype(np.int8))
        self._last_t = float(t[-1])

    def start(self, t_s: float) -> None:
        """Start the filter at ``t_s`` (e.g. the start of an evaluation window) before any observation.

        The public Perpetua reference starts every feature's filter there, in the present state;
        filters that keep a survival clock (``perpetua``) set its origin to ``t_s``. The default does
        nothing. Raises :class:`EstimatorError` once an observation has been applied.
        """
        if self._last_t is not None:
            raise EstimatorError(f"edge {self.edge}: start() must come before the first observation")

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """P(present) at times ``t_s`` (any shape); times before the last observation are clamped to it."""
        t = np.asarray(t_s, dtype=np.float64)
        if t.size == 1:
            return self._predict_one(t)
        if not np.isfinite(t).all():
            raise EstimatorError(f"edge {self.edge}: query times must be finite")
        if self._last_t is not None:
            t = np.maximum(t, self._last_t)
        out = np.asarray(self._predict(t.reshape(-1)), dtype=np.float64).reshape(t.shape)
        if not self._repairs_predictions:
            return out  # a plugin's values as they are: psg-eval checks them and reports NaN or out of range
        # NaN -> 0.5, then [0, 1] (+-inf clip to 1 and 0, as nan_to_num's +-max would; two ufuncs, not nan_to_num)
        return np.clip(np.where(np.isnan(out), 0.5, out), 0.0, 1.0)

    def _predict_one(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`predict` of a single time with Python floats around ``_predict``: the same numbers
        without numpy's per-call cost (psg-eval's adaptive loop asks for one time per call).
        """
        x = float(t.reshape(-1)[0])
        if not math.isfinite(x):
            raise EstimatorError(f"edge {self.edge}: query times must be finite")
        if self._last_t is not None and x < self._last_t:
            x = self._last_t
        out = np.asarray(self._predict(np.array([x])), dtype=np.float64).reshape(t.shape)
        if not self._repairs_predictions:
            return out
        v = float(out.reshape(-1)[0])
        v = 0.5 if v != v else 0.0 if v < 0.0 else 1.0 if v > 1.0 else v  # np.clip(np.where(isnan, 0.5, .)): -0.0 kept
        return np.float64(v) if t.ndim == 0 else np.full(t.shape, v)  # as numpy's ufuncs return a 0-d result

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:  # pragma: no cover
        raise NotImplementedError

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover
        raise NotImplementedError


TRAINING_PARAMETERS: dict[str, Param] = {
    "max_components": Integral(1, 10, help="largest number of mixture components tried by AIC"),
    "survival": Options(*INTERVAL_FAMILIES, help="survival family of the persistence / emergence mixtures"),
    "p_m": Real(0.0, 0.5, none_ok=True, help="P(seen absent | present); none: estimated from the training data"),
    "p_f": Real(0.0, 0.5, none_ok=True, help="P(seen present | absent); none: estimated from the training data"),
    "segmentation": Options(*SEGMENTATIONS, help="states of the training observations: hmm, observations, "
                            "reference (the public Perpetua's L2 PELT) or bernoulli (PELT, min_segment / "
                            "segment_penalty)"),
    "durations": Options("segments", "ground_truth", "auto", help="where training run durations come from"),
    "min_segment": Integral(1, None, help="bernoulli segmentation: shortest segment, observations"),
    "segment_penalty": Real(0.0, None, help="bernoulli segmentation: change-point penalty, nats"),
    "pool_weight": Real(0.0, None, help="total weight of the pooled runs added to each edge's own (shrinkage)"),
    "sigma_min": Real(0.0, None, closed="neither", help="floor of sigma of ln T of log-normal components"),
    "escape": Real(0.0, 1e-3, help="floor of the change probability per interval (first interval: 1e-6 or this "
                   "if larger; 0 disables both)"),
    "random_state": Integral(0, None, help="seed of the EM restarts"),
}
"""Settings shared by the estimators trained on interval-censored runs (Perpetua*, Perpetua)."""


def fit_training(est: Any, streams: Sequence[EdgeStream]) -> dict[str, Any]:
    """Shared training of Perpetua and Perpetua*: states, runs, error rates and survival mixtures.

    Sets ``est.p_m_``, ``est.p_f_``, ``est.survivals_`` (edge -> (persistence, emergence)),
    ``est.default_survivals_`` and returns the training part of the fit summary.
    """
    data = training_runs(streams, segmentation=est.segmentation, durations=est.durations, p_m=est.p_m, p_f=est.p_f,
                         min_segment=int(est.min_segment), segment_penalty=float(est.segment_penalty))
    est.p_m_, est.p_f_ = float(data.p_m), float(data.p_f)
    est.survivals_, est.default_survivals_, per_edge = fit_edge_survivals(
        data, family=est.survival, max_components=int(est.max_components), pool_weight=float(est.pool_weight),
        sigma_min=float(est.sigma_min), seed=int(est.random_state))
    return {"segmentation": data.segmentation, "durations": est.durations,
            "error_rates": {"p_m": est.p_m_, "p_f": est.p_f_, "source": data.error_source,
                            **({"hmm": data.hmm.summary()} if data.hmm is not None else {})},
            "edges": {f"{e[0]}/{e[1]}": v for e, v in per_edge.items()}}


def escape_floors(escape: float) -> tuple[float, float]:
    """(escape, escape_first) of a filter from the ``escape`` setting (0 disables both)."""
    e = float(escape)
    return (0.0, 0.0) if e <= 0 else (e, max(ESCAPE_FIRST, e))


def _say_once(text: str) -> None:
    """An INFO line marked ``say_once``: the command line's log handler prints it once per command
    (a run refits the same estimator per seed, scene and method); library logging sees every one.
    """
    log.info("%s", text, extra={"say_once": True})


def log_fit_summary(name: str, summary: Mapping[str, Any]) -> None:
    """One INFO line per decided setting and the error rates (the full summary is ``fit_summary_``),
    each marked ``say_once`` (:func:`_say_once`).
    """
    for k, v in summary.get("settings", {}).items():
        _say_once(f"{name}: {k} = {v.get('value')} ({v.get('source')})")
    er = summary.get("error_rates")
    if er:
        _say_once(f"{name}: P_M = {er['p_m']:.4f}, P_F = {er['p_f']:.4f} ({er['source']})")
    osel = summary.get("order_selection")
    if osel:
        _say_once(f"{name}: FreMEn order rule {osel['order_rule']}, duration rule "
                  f"{'on' if osel['duration_rule'] else 'off'}, median order {osel['median_order']} over "
                  f"{len(osel['edges'])} edges")
