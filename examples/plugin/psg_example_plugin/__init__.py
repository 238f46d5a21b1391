"""An example psg-data estimator plugin (README, "Estimators and plugins").

``example_decay``: after an observation y at t0, P(present at t) = w y + (1 - w) p, with
w = 0.5 ** ((t - t0) / half_life) and p the edge's share of present training observations (the
pooled share for an edge without training data). ``BaseEstimator`` gives it scikit-learn's
settings handling and the fitted / state checks, ``BaseFilter`` the time checks and the state's common
keys (``psg_data.estimators.STATE_KEYS``); only public members are used; ``check_estimator`` passes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.estimators import BaseEstimator, BaseFilter, EdgeKey, EdgeStream, Real

__all__ = ["DecayEstimator", "DecayFilter"]


class DecayFilter(BaseFilter):
    """The last observation, decaying to the edge's base rate ``prior`` with ``half_life_s`` (s)."""

    def __init__(self, edge: EdgeKey, prior: float, half_life_s: float, name: str) -> None:
        super().__init__(edge)
        self.prior, self.half_life_s, self._name = float(prior), float(half_life_s), name
        self.last_y: int | None = None

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        self.last_y = int(y[-1])

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.last_y is None or self.last_t_s is None:
            return np.full(t.shape, self.prior)
        w = 0.5 ** ((t - self.last_t_s) / self.half_life_s)
        return w * self.last_y + (1.0 - w) * self.prior

    def get_state(self) -> dict[str, Any]:
        """JSON-serialisable state: the common keys (estimator, edge, last_t_s) and this filter's own
        (``DecayEstimator.filter_from_state`` restores it).
        """
        return {**self.base_state(self._name), "last_y": self.last_y, "prior": self.prior}


class DecayEstimator(BaseEstimator):
    """The last observation decaying to the edge's base rate.

    Args:
        half_life_h: hours after which the last observation has half its weight.
    """

    name = "example_decay"
    _parameters = {"half_life_h": Real(0.0, None, closed="neither", help="half-life of an observation, hours")}

    def __init__(self, *, half_life_h: float = 6.0) -> None:
        self.half_life_h = half_life_h

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> DecayEstimator:
        """Learn each edge's share of present observations; return self."""
        self.validate_params()
        ys: dict[EdgeKey, list[NDArray[Any]]] = {}
        for s in streams:
            ys.setdefault(s.edge, []).append(np.asarray(s.y))
        self.priors_ = {e: float(np.concatenate(v).mean()) for e, v in ys.items() if sum(len(a) for a in v)}
        self.default_prior_ = float(np.mean(list(self.priors_.values()))) if self.priors_ else 0.5
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> DecayFilter:
        """A fresh filter for ``edge``."""
        self.check_fitted()
        return DecayFilter(edge, self.priors_.get(edge, self.default_prior_), 3600.0 * self.half_life_h, self.name)

    def filter_from_state(self, state: dict[str, Any]) -> DecayFilter:
        """The filter ``DecayFilter.get_state`` described."""
        edge = self.edge_of_state(state)
        f = DecayFilter(edge, state["prior"], 3600.0 * self.half_life_h, self.name)
        f.last_y = state["last_y"]
        f.restore_state(state)
        return f
