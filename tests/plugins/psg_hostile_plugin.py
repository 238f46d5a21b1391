"""A hostile estimator plugin (tests only): each entry point breaks one rule of the plugin contract.

Installed by ``tests/plugins/install.py`` as a distribution of its own with an ``entry_points.txt``
in the ``psg_data.estimators`` group, as ``pip install`` would; psg-eval must report each estimator's
failure and score the others.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

from psg_data.estimators import BaseEstimator, BaseFilter


class _Filter(BaseFilter):
    """The last observation (0.5 before any), with one hook per attack."""

    def __init__(self, edge: Any, mode: str) -> None:
        super().__init__(edge)
        self.mode, self.last_y = mode, None

    def _update_many(self, t: np.ndarray, y: np.ndarray) -> None:
        self.last_y = int(y[-1])

    def _predict(self, t: np.ndarray) -> np.ndarray:
        if self.mode == "nan":
            return np.full(t.shape, np.nan)
        if self.mode == "out_of_range":
            return np.full(t.shape, 1.5)
        return np.full(t.shape, 0.5 if self.last_y is None else float(self.last_y))

    def predict(self, t_s: Any) -> np.ndarray:
        if self.mode == "predict_raises":
            raise RuntimeError("predict boom")
        if self.mode == "sleeps":
            time.sleep(3600)
        if self.mode == "wrong_shape":
            return np.zeros(np.size(t_s) + 1)
        return super().predict(t_s)

    def update_many(self, t_s: Any, y: Any) -> None:
        if self.mode == "edits" and np.size(t_s):
            np.asarray(y)[...] = 0  # in place: the caller's array (every observation made "absent")
        super().update_many(t_s, y)

    def get_state(self) -> dict[str, Any]:
        return {"estimator": "hostile", "edge": list(self.edge), "last_t_s": self._last_t, "last_y": self.last_y}


class _Hostile(BaseEstimator):
    name = "hostile"
    mode = "good"

    def __init__(self) -> None:
        if self.mode == "init_raises":
            raise RuntimeError("init boom")

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        if self.mode == "params_raise":
            raise RuntimeError("get_params boom")
        return {}

    def fit(self, streams: Any, *, val_streams: Any = None, timezone: str = "UTC") -> Any:
        if self.mode == "fit_raises":
            raise RuntimeError("fit boom")
        if self.mode == "exits":
            sys.exit(0)
        if self.mode == "edits":
            for s in streams:
                s.y[...] = 1 - s.y  # in place: every other estimator's training data
        self.fitted_ = True
        return self

    def make_filter(self, edge: Any) -> Any:
        self._check_fitted()
        if self.mode == "make_filter_raises":
            raise RuntimeError("make_filter boom")
        if self.mode == "make_filter_none":
            return None
        return _Filter(edge, self.mode)

    def filter_from_state(self, state: dict[str, Any]) -> Any:
        f = _Filter(self._check_state(state), self.mode)
        f._last_t, f.last_y = state["last_t_s"], state["last_y"]
        return f


MODES = ("good", "fit_raises", "make_filter_raises", "make_filter_none", "predict_raises", "wrong_shape", "nan",
         "out_of_range", "edits", "exits", "sleeps", "init_raises", "params_raise")


def _make(mode: str) -> type:
    return type(f"Hostile_{mode}", (_Hostile,), {"mode": mode, "name": f"hostile_{mode}", "__module__": __name__})


for _m in MODES:
    globals()[f"Hostile_{_m}"] = _make(_m)
