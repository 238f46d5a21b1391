"""The ``fremen`` estimator and the per-edge FreMEn fitting shared with Perpetua*'s FreMEn prior."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._cadence import training_cadence
from psg_data.estimators._common import BaseEstimator, BaseFilter, log_fit_summary, streams_by_edge
from psg_data.estimators._fremen import WEEK_S, FremenComponents, FremenModel, LocalClock, choose_order
from psg_data.estimators._params import Integral, Real

__all__ = ["FremenEstimator", "FremenFilter", "fit_fremen_edge", "training_clock"]


def training_clock(streams: Sequence[EdgeStream], timezone: str) -> LocalClock:
    """Reference epoch: the local Monday 00:00 before the first training observation."""
    firsts = [float(s.t_s[0]) for s in streams if len(s)]
    return LocalClock.before(min(firsts) if firsts else 0.0, timezone)


def _cat(streams: Sequence[EdgeStream]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    if not streams:
        return np.zeros(0), np.zeros(0)
    return (np.concatenate([s.t_s for s in streams]), np.concatenate([s.y for s in streams]).astype(np.float64))


def fit_fremen_edge(train: Sequence[EdgeStream], val: Sequence[EdgeStream] | None, clock: LocalClock, *,
                    n_periods: int, order_tol: float, max_order: int | None) -> tuple[FremenComponents, dict[str, Any]]:
    """Fit FreMEn on ``train``; choose the order (top-m by amplitude) on ``val``.

    Without validation data the last week of ``train`` is held out to choose the order (the model is
    then refit on all training data with that order).
    """
    t, y = _cat(train)
    tau = clock(t)
    model = FremenModel(n_periods).add(tau, y)
    vt, vy = _cat(val or [])
    info: dict[str, Any] = {"validation": "val_streams"}
    if vt.size:
        errs = model.validation_errors(clock(vt), vy, max_order)
    elif t.size and (t.max() - t.min()) > 1.5 * WEEK_S:
        cut = t.max() - WEEK_S
        held = t >= cut
        sub = FremenModel(n_periods).add(tau[~held], y[~held])
        errs = sub.validation_errors(tau[held], y[held], max_order)
        info["validation"] = "last training week"
    else:
        errs = np.zeros(1)
        info["validation"] = "none (order 0)"
    order = choose_order(errs, order_tol)
    info["order"] = order
    info["val_mae"] = float(errs[order])
    return model.components(order), info


class FremenFilter(BaseFilter):
    """FreMEn predictions; updates only record the last time (FreMEn does not adapt online)."""

    def __init__(self, edge: EdgeKey, comps: FremenComponents, clock: LocalClock, name: str = "fremen") -> None:
        super().__init__(edge)
        self.comps = comps
        self.clock = clock
        self._name = name

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        pass

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.comps.predict(self.clock(t))

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t,
                "components": self.comps.to_dict(), "clock": self.clock.to_dict()}


class FremenEstimator(BaseEstimator):
    """FreMEn (Krajnik et al. 2017) with weekly harmonics, order chosen on held-out data.

    Args:
        n_periods: K candidate periods one week / k, k = 1..K; None: the shortest period is twice
            the training streams' typical gap between observations (Nyquist; at most 1000, see
            :mod:`~psg_data.estimators._cadence`). Recorded in ``fit_summary_``.
        max_order: largest order tried on the validation data (None: K).
        order_tol: tolerance (MAE) favouring smaller orders.
    """

    name = "fremen"
    _parameters = {
        "n_periods": Integral(0, None, none_ok=True, help="candidate periods one week / k, k = 1..n_periods; none: "
                              "shortest period twice the typical gap between observations (at most 1000)"),
        "max_order": Integral(0, None, none_ok=True, help="largest order tried on validation data (none: n_periods)"),
        "order_tol": Real(0.0, None, help="MAE tolerance favouring smaller orders"),
    }

    def __init__(self, *, n_periods: int | None = None, max_order: int | None = None, order_tol: float = 1e-3) -> None:
        self.n_periods = n_periods
        self.max_order = max_order
        self.order_tol = order_tol

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> FremenEstimator:
        """Fit per-edge models to the training streams (times in s, UTC); returns self."""
        self.validate_params()
        tr = streams_by_edge(streams)
        va = streams_by_edge(val_streams)
        self.clock_ = training_clock(list(streams), timezone)
        cad = training_cadence(list(streams))
        self.n_periods_ = int(self.n_periods) if self.n_periods is not None else cad.n_periods
        self.fit_summary_ = {"estimator": self.name, "cadence": cad.to_dict(), "settings": {"n_periods": {
            "value": self.n_periods_, "source": "set" if self.n_periods is not None else
            f"cadence: typical gap {cad.typical_gap_s:g} s"}}}
        log_fit_summary(self.name, self.fit_summary_)
        self.components_: dict[EdgeKey, FremenComponents] = {}
        self.fit_info_: dict[EdgeKey, dict[str, Any]] = {}
        for e, ss in tr.items():
            self.components_[e], self.fit_info_[e] = fit_fremen_edge(
                ss, va.get(e), self.clock_, n_periods=self.n_periods_, order_tol=self.order_tol,
                max_order=self.max_order)
        allt = [s for s in streams if len(s)]
        mean = float(np.mean(np.concatenate([s.y for s in allt]))) if allt else 0.5
        self.default_ = FremenComponents(mean, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.complex128))
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> FremenFilter:
        """A new filter for ``edge`` (object_id, receptacle_id) with the fitted models, before any observation."""
        self._check_fitted()
        return FremenFilter(edge, self.components_.get(edge, self.default_), self.clock_)

    def filter_from_state(self, state: dict[str, Any]) -> FremenFilter:
        """The filter that :meth:`get_state` of one of this estimator's filters described."""
        edge = self._check_state(state)
        if "components" in state:  # self-contained (psg-data >= 0.2.0 with graphs): no fit needed
            f = FremenFilter(edge, FremenComponents.from_dict(state["components"]),
                             LocalClock.from_dict(state["clock"]), self.name)
        else:
            f = self.make_filter(edge)
        f._last_t = state["last_t_s"]
        return f
