"""Reference copy of Perpetua's filter (``PerpetuaFilter``, psg_data/estimators/_perpetua.py) as of main
8f53f6f (issue 45), kept unchanged.

The package's filter was made cheap (the mixtures' prediction terms cached between updates, scalar
switching checks, a shallow copy for predictions); the tests compare it with this original on the
demo's edges, a navigation benchmark scene and random inputs. Do not edit except to follow API
renames.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.estimators._base import EdgeKey
from psg_data.estimators._common import BaseFilter, escape_floors
from psg_data.estimators._mixture import ESCAPE, ESCAPE_FIRST, MixtureFilter
from psg_data.estimators._survival import SurvivalMixture

__all__ = ["PerpetuaFilter", "reference_filter"]


class PerpetuaFilter(BaseFilter):
    def __init__(self, edge: EdgeKey, per: SurvivalMixture, emg: SurvivalMixture, p_m: float, p_f: float, *,
                 delta_low: float, delta_high: float, eps: float, num_steps: int, escape: float = ESCAPE,
                 escape_first: float = ESCAPE_FIRST, name: str = "perpetua") -> None:
        super().__init__(edge)
        self.per = MixtureFilter(per, p_m, p_f, escape=escape, escape_first=escape_first)
        self.emg = MixtureFilter(emg, p_m, p_f, emergence=True, escape=escape, escape_first=escape_first)
        self.delta_low = float(delta_low)
        self.delta_high = float(delta_high)
        self.eps = float(eps)
        self.num_steps = int(num_steps)
        self.active = "per"
        self._name = name

    def _reset_weights(self, m: MixtureFilter) -> NDArray[np.float64]:
        w0 = m.survival.weights
        w = (1 - self.eps) * m.posterior_weights() + self.eps * w0 if m.started else w0
        with np.errstate(divide="ignore"):
            return np.log(w)

    def _switch(self, t: float) -> None:
        if self.active == "per":
            lp = self._reset_weights(self.emg)
            self.emg.reset(t)
            self.emg.log_prior = lp
            self.active = "emg"
        else:
            lp = self._reset_weights(self.per)
            self.per.reset(t)
            self.per.log_prior = lp
            self.active = "per"

    def _crossed(self, m: MixtureFilter, t: NDArray[np.float64]) -> NDArray[np.bool_]:
        p = m.predict(t)
        return p <= self.delta_low if self.active == "per" else p >= self.delta_high

    def _simulate(self, grid: NDArray[np.float64]) -> None:
        """Advance the state machine over sorted times (no observations)."""
        i = 0
        while i < grid.size:
            m = self.per if self.active == "per" else self.emg
            hit = np.flatnonzero(self._crossed(m, grid[i:]))
            if hit.size == 0:
                return
            self._switch(float(grid[i + hit[0]]))
            i += int(hit[0]) + 1

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        for ti, yi in zip(t.tolist(), y.tolist()):
            if self._last_t is not None and ti > self._last_t and self.num_steps > 0:
                sub = np.linspace(self._last_t, ti, self.num_steps + 2)[1:-1]
                self._simulate(sub)
            self.per.update(ti, yi)
            if self.emg.started:
                self.emg.update(ti, yi)
            self._simulate(np.array([ti]))
            self._last_t = ti

    def start(self, t_s: float) -> None:
        """Start in the persistence state with the survival clock at ``t_s`` (before any observation)."""
        super().start(t_s)
        self.per.reset(float(t_s))
        self.active = "per"

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        t0 = self._last_t if self._last_t is not None else self.per.origin
        if t0 is None:  # never started: the present state
            return np.ones(t.shape)
        t = np.maximum(t, t0)
        order = np.argsort(t, kind="stable")
        ts = t[order]
        # simulation grid: query times plus num_steps sub-steps between consecutive distinct times
        knots = np.unique(np.concatenate([[t0], ts]))
        if self.num_steps > 0 and knots.size > 1:
            frac = np.arange(1, self.num_steps + 1) / (self.num_steps + 1)
            sub = (knots[:-1, None] + np.diff(knots)[:, None] * frac).reshape(-1)
            grid = np.unique(np.concatenate([knots, sub]))
        else:
            grid = knots
        sim = self._copy()
        out_sorted = np.empty(ts.size)
        # walk the grid phase by phase; queries are answered by the model active at their time
        i = 0
        q = 0
        while q < ts.size:
            m = sim.per if sim.active == "per" else sim.emg
            hit = np.flatnonzero(sim._crossed(m, grid[i:]))
            end = grid[i + hit[0]] if hit.size else np.inf
            # queries strictly before the switch time use the current model
            qe = int(np.searchsorted(ts, end, side="left"))
            out_sorted[q:qe] = m.predict(ts[q:qe])
            q = qe
            if hit.size == 0:
                break
            sim._switch(float(end))
            i += int(hit[0]) + 1
        out = np.empty(ts.size)
        out[order] = out_sorted
        return out

    def _copy(self) -> PerpetuaFilter:
        c = PerpetuaFilter(self.edge, self.per.survival, self.emg.survival, self.per.p_m, self.per.p_f,
                           delta_low=self.delta_low, delta_high=self.delta_high, eps=self.eps,
                           num_steps=self.num_steps, escape=self.per.escape, escape_first=self.per.escape_first,
                           name=self._name)
        c.per.set_state(self.per.get_state())
        c.emg.set_state(self.emg.get_state())
        c.active = self.active
        c._last_t = self._last_t
        return c

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t, "active": self.active,
                "per": self.per.get_state(), "emg": self.emg.get_state(),
                "per_survival": self.per.survival.to_dict(), "emg_survival": self.emg.survival.to_dict(),
                "p_m": self.per.p_m, "p_f": self.per.p_f, "delta_low": self.delta_low, "delta_high": self.delta_high,
                "eps": self.eps, "num_steps": self.num_steps, "escape": [self.per.escape, self.per.escape_first]}

    @classmethod
    def from_state(cls, s: dict[str, Any]) -> PerpetuaFilter:
        f = cls((s["edge"][0], s["edge"][1]), SurvivalMixture.from_dict(s["per_survival"]),
                SurvivalMixture.from_dict(s["emg_survival"]), s["p_m"], s["p_f"], delta_low=s["delta_low"],
                delta_high=s["delta_high"], eps=s["eps"], num_steps=s["num_steps"], escape=s["escape"][0],
                escape_first=s["escape"][1], name=s["estimator"])
        f.per.set_state(s["per"])
        f.emg.set_state(s["emg"])
        f.active = s["active"]
        f._last_t = s["last_t_s"]
        return f


def reference_filter(estimator: Any, edge: EdgeKey) -> PerpetuaFilter:
    """The reference filter of ``edge`` built from a fitted ``PerpetuaEstimator`` as its ``make_filter`` does."""
    edge = (str(edge[0]), str(edge[1]))
    per, emg = estimator.survivals_.get(edge, estimator.default_survivals_)
    esc, esc1 = escape_floors(estimator.escape)
    return PerpetuaFilter(edge, per, emg, estimator.p_m_, estimator.p_f_, delta_low=float(estimator.delta_low),
                          delta_high=float(estimator.delta_high), eps=float(estimator.eps),
                          num_steps=int(estimator.num_steps), escape=esc, escape_first=esc1, name=estimator.name)
