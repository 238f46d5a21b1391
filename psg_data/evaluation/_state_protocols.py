"""The two protocols of the real long-term benchmarks (:mod:`psg_data.loaders.raw._state_benchmarks`).

``published`` (the authors' own, ``DoorState.hs`` of ``chronorobotics/framework2``)
    every estimator is fitted on the dense training rows (one observation per minute) and forecasts
    each test period with no test observation (the predictive setting); the error of a period is
    the mean squared error of the predicted probability over its rows (``mse``, their metric).

``patrol`` (a robot's patrol: the setting psg-data exists for)
    the robot observes the state only at a patrol cadence (default every 2 h from 09:00 to 17:00
    local time, :class:`PatrolPlan`; optional flips P_M / P_F) in the training weeks and in the test
    period; in the adaptive setting the test period's patrol observations update the filters online
    and the prediction at ``t`` has those up to ``t - horizon`` (default: one patrol interval); in
    the predictive setting none. Scored against every published row of the period.

Both score every row of the period (the whole day; a gap's interval gets no weight, see the
loader). A period is one draw: the summary is the mean over periods with a t-interval, and every
period's row is kept.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.evaluation._edge_run import EdgeJob, ScoreConfig
from psg_data.metrics._time_weights import trapezoid_weights

__all__ = ["STATE_PROTOCOLS", "PatrolPlan", "patrol_streams", "edge_jobs", "score_config"]

STATE_PROTOCOLS = {
    "published": "the authors' protocol: fit on the dense training rows, forecast each test week with no test "
                 "observation; error = mean squared error of the predicted probability per week",
    "patrol": "a robot's patrol: observations only at the patrol times, in training and in the test week (adaptive: "
              "online with a forecast horizon; predictive: none); scored on every published row",
}


@dataclass(frozen=True)
class PatrolPlan:
    """Patrol times: every ``step_h`` hours from ``start_h`` to ``end_h`` (inclusive), local time, every day.

    Attributes:
        start_h, end_h, step_h: hours (local wall-clock time of the benchmark's clock).
        p_m: probability that a present state is observed absent (a miss).
        p_f: probability that an absent state is observed present (a false positive).
        seed: seed of the flips.
    """

    start_h: float = 9.0
    end_h: float = 17.0
    step_h: float = 2.0
    p_m: float = 0.0
    p_f: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not (0.0 <= self.start_h <= self.end_h < 24.0 and self.step_h > 0):
            raise EvaluationError(f"patrol {self.start_h:g}-{self.end_h:g}/{self.step_h:g}h: expected "
                                  "0 <= start <= end < 24 and a positive step, e.g. 9-17/2h")
        if not (0.0 <= self.p_m < 0.5 and 0.0 <= self.p_f < 0.5):
            raise EvaluationError(f"patrol flips P_M={self.p_m}, P_F={self.p_f}: expected both in [0, 0.5)")

    @classmethod
    def parse(cls, text: str, **kw: Any) -> PatrolPlan:
        """``"9-17/2h"`` (hours; ``/30min`` also), as ``--dataset door-benchmark:patrol=9-17/2h``."""
        m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)-(\d+(?:\.\d+)?)/(\d+(?:\.\d+)?)(h|min)\s*", str(text))
        if not m:
            raise EvaluationError(f"patrol {text!r}: expected START-END/STEP in local hours, e.g. 9-17/2h or "
                                  "8-18/30min")
        step = float(m.group(3)) / (60.0 if m.group(4) == "min" else 1.0)
        return cls(float(m.group(1)), float(m.group(2)), step, **kw)

    @property
    def hours(self) -> NDArray[np.float64]:
        """The patrol's local hours of a day."""
        n = int(np.floor((self.end_h - self.start_h) / self.step_h + 1e-9)) + 1
        return np.asarray(self.start_h + self.step_h * np.arange(n), dtype=np.float64)

    @property
    def label(self) -> str:
        """``09:00-17:00 every 2 h``."""
        def hm(h: float) -> str:
            return f"{int(h):02d}:{int(round((h % 1) * 60)):02d}"
        return f"{hm(self.start_h)}-{hm(self.end_h)} every {self.step_h * 60:g} min" if self.step_h < 1 else \
            f"{hm(self.start_h)}-{hm(self.end_h)} every {self.step_h:g} h"

    def times(self, lo_s: float, hi_s: float, timezone: str) -> NDArray[np.float64]:
        """Patrol stamps (UTC seconds) in ``[lo_s, hi_s]``, local times in ``timezone`` (DST-aware)."""
        import pandas as pd

        days = pd.date_range(pd.Timestamp(lo_s, unit="s", tz="UTC").tz_convert(timezone).normalize().tz_localize(None),
                             pd.Timestamp(hi_s, unit="s", tz="UTC").tz_convert(timezone).normalize().tz_localize(None),
                             freq="D")
        local = (days.values[:, None] + (self.hours * 3600e9).astype("timedelta64[ns]")[None, :]).reshape(-1)
        stamps = pd.DatetimeIndex(local).tz_localize(timezone, ambiguous="NaT", nonexistent="NaT").dropna()
        t = stamps.asi8.astype(np.float64) / 1e9
        return np.sort(t[(t >= lo_s) & (t <= hi_s)])


def patrol_streams(rows: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[Any]]], plan: PatrolPlan, timezone: str,
                   *, complement: bool = False, salt: int = 0) -> list[EdgeStream]:
    """The rows each patrol time sees (a row with exactly that stamp; a gap gives none), with seeded flips.

    Args:
        rows: edge -> (t_s, state) of the dense rows (codes below 0 are never observed).
        plan: the patrol.
        timezone: the clock of local time.
        complement: the edges are one door's (open, closed): only the first is flipped and the
            second is its complement (one observation of the door, as door labels are made).
        salt: mixed into the flip seed (training and each test period draw different flips).
    """
    rng = np.random.default_rng([int(plan.seed), int(salt)])
    out: list[EdgeStream] = []
    first: NDArray[np.int8] | None = None
    spans: dict[tuple[float, float], NDArray[np.float64]] = {}  # the edges of a benchmark share their rows' span
    for k, (e, (t, y)) in enumerate(rows.items()):
        span = (float(t[0]), float(t[-1])) if t.size else (0.0, -1.0)
        if span not in spans:
            spans[span] = plan.times(*span, timezone) if t.size else np.zeros(0)
        pt = spans[span]
        i = np.clip(np.searchsorted(t, pt), 0, max(t.size - 1, 0))
        hit = (t.size > 0) & (np.abs(t[i] - pt) < 0.5) & (np.asarray(y)[i] >= 0)
        ts, ys = pt[hit], np.asarray(y)[i[hit]].astype(np.int8)
        if complement and k == 1 and first is not None:
            ys = (1 - first).astype(np.int8)
        else:
            u = rng.random(ys.size)
            flip = np.where(ys == 1, u < plan.p_m, u < plan.p_f)
            ys = np.where(flip, 1 - ys, ys).astype(np.int8)
            first = ys
        out.append(EdgeStream(e, ts, ys))
    return out


def score_config(setting: str, horizon_s: float) -> ScoreConfig:
    """psg-eval's scoring conventions (threshold 0.5, the reference convention, codes -1/-2 excluded)."""
    from psg_data.evaluation._options import PersistenceOptions

    o = PersistenceOptions()
    return ScoreConfig(setting, float(horizon_s), float(o.threshold), o.convention, o.sample_convention,
                       tuple(o.codes))


def edge_jobs(truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]], edges: tuple[EdgeKey, ...],
              history: dict[EdgeKey, EdgeStream], test: dict[EdgeKey, EdgeStream], draw: int,
              timezone: str) -> list[EdgeJob]:
    """One job per scored edge: its history, test observations and every row of the period as evaluation times."""
    from psg_data.evaluation._persistence_task import _weekdays

    empty_t, empty_y = np.zeros(0), np.zeros(0, dtype=np.int8)
    jobs = []
    for e in edges:
        t, y = truth[e]
        valid = y >= 0
        h, s = history.get(e), test.get(e)
        jobs.append(EdgeJob(e, h.t_s if h else empty_t, h.y if h else empty_y, s.t_s if s else empty_t,
                            s.y if s else empty_y, t, y, trapezoid_weights(t, valid), _weekdays(t, timezone),
                            keep=True, draw=draw))
    return jobs
