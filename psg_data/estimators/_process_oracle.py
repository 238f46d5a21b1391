"""``process_oracle``: the exact Bayes posterior of a synthetic lab's generative model (the ceiling).

A dataset written by ``psg-data synth`` with the ``steps-v2`` generator stores its generative
model (``generator/process.json``: every entity's hierarchical step process, see
:mod:`psg_data.schemas._generator_model`; the forward algorithm is in
:mod:`psg_data.synth._process`). Given an entity's observations, the posterior over its state
(receptacle or absent; door open or closed) at any later step is computed exactly by the forward
algorithm over (day pattern x state x remaining dwell); the prediction for edge (entity, label)
is P(state = label). No estimator that sees the same observations can do better in expectation.

Information used by the filter of edge ``(o, r)`` (never anything later than the filter's own last
update time ``H``, whatever order the filters are built, updated or asked in):

* its own observations (those given to ``update`` / ``update_many``);
* the observations of the object's other edges ``(o, r')`` from the training streams handed to
  :meth:`ProcessOracleEstimator.fit`, restricted to times ``<= H``;
* with ``share_updates=True``: also the observations later than the training data that sibling
  filters of the same fitted estimator received (a per-object tracker), restricted to ``<= H``.
  Off by default: the per-edge protocol feeds every filter only its own test observations, and
  what a sibling filter has seen depends on the order (and worker process) in which the harness
  runs the edges; without the tracker the information set of a filter is exactly what a per-edge
  estimator can know, so the ceiling is reproducible and independent of ``jobs``.

Before any observation (``last_t_s`` None) the prediction is the model's prior marginal.

Two readings (``model``): ``generating`` (default), the posterior under the model that generated
the data, test-week regime included (the ceiling); ``train``, the posterior under the training model
only (:meth:`~psg_data.schemas._generator_model.StepProcess.base_model`: the stored process without
its regimes), the best a predictor that does not adapt to a test-time shift can do. On a dataset
without a shift the two are the same model.

What the ceiling is a ceiling of: the posterior probability (``output="probability"``, default) is
the best possible prediction for proper scores (log loss, Brier) and, thresholded at 0.5, the most
accurate present/absent decision at every time. MAE is not a proper score: its optimum is the
posterior median, the 0/1 decision ``P >= 0.5`` (``output="median"``); a hard predictor such as
``last_seen`` can beat the probability's MAE where the state is nearly certain. Balanced accuracy
and F1 at the fixed threshold 0.5 are not maximised exactly by any fixed rule either (their best
threshold depends on each edge's class balance); both outputs give the same decisions there.
Observations are noise-free by default (ground-truth and privileged labels); declare ``p_m`` /
``p_f`` for noisy labels. An observation impossible under the model raises
:class:`~psg_data.errors.EstimatorError` (wrong dataset, or noisy labels with zero noise rates).
"""

from __future__ import annotations

import bisect
import copy
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError, PsgDataError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._common import BaseEstimator, BaseFilter
from psg_data.estimators._params import Boolean, MappingParam, Options, Real, Text

__all__ = ["ProcessOracleEstimator", "ProcessOracleFilter"]

log = logging.getLogger(__name__)


@dataclass
class _Tracker:
    """Observations of one object's filters later than the training data (``share_updates``)."""

    t: list[float] = field(default_factory=list)
    label: list[str] = field(default_factory=list)
    y: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class _EntityData:
    """Training observations of one entity, sorted by time."""

    t: NDArray[np.float64]
    label: NDArray[np.object_]
    y: NDArray[np.int8]


def median_of(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """The 0/1 median of P(present) = ``p``: 1 where ``p >= 0.5`` (``output="median"``)."""
    return (np.asarray(p) >= 0.5).astype(np.float64)


class ProcessOracleEstimator(BaseEstimator):
    """The exact posterior under a synthetic dataset's stored generator model (see the module docstring).

    Args:
        dataset: a dataset directory written by ``psg-data synth`` (generator ``steps-v2``), or the
            path of its ``generator/process.json``. ``psg-eval`` fills it in for such datasets.
        process: the process as a dict (the parsed JSON) or a ``StepProcess``; overrides ``dataset``.
        model: ``generating`` (the model that generated the data, the ceiling) or ``train`` (the
            training model only, regimes dropped; module docstring).
        p_m: P(seen absent | present) of the observations (0 for ground-truth / privileged labels).
        p_f: P(seen present | absent) of the observations.
        share_updates: also use the post-training observations that sibling filters of the same
            object received (order-dependent; see the module docstring).
        output: ``probability`` (the posterior P(present)) or ``median`` (its 0/1 median, the
            Bayes decision for MAE).
    """

    name = "process_oracle"
    _parameters = {
        "dataset": Text(help="synthetic dataset (or its generator/process.json) carrying the generator model"),
        "process": MappingParam(help="the generator process as a dict (Python API; overrides dataset)"),
        "model": Options("generating", "train", help="posterior under the generating model (the ceiling) or the "
                                                     "training model only (regimes dropped)"),
        "p_m": Real(0.0, 0.5, closed="left", help="P(seen absent | present) of the labels"),
        "p_f": Real(0.0, 0.5, closed="left", help="P(seen present | absent) of the labels"),
        "share_updates": Boolean(help="filters of one object share their post-training observations"),
        "output": Options("probability", "median", help="posterior probability, or its 0/1 median (MAE)"),
    }

    def __init__(self, *, dataset: str | None = None, process: Mapping[str, Any] | None = None,
                 model: str = "generating", p_m: float = 0.0, p_f: float = 0.0, share_updates: bool = False,
                 output: str = "probability") -> None:
        self.dataset = dataset
        self.process = process
        self.model = model
        self.p_m = p_m
        self.p_f = p_f
        self.share_updates = share_updates
        self.output = output

    def derived_output(self) -> tuple[dict[str, Any], Any] | None:
        """With ``output="median"``: (the parameters of the probability row, :func:`median_of`): its
        predictions are the median of that row's, so psg-eval scores it from them (one filter per
        edge); None otherwise.
        """
        if self.output != "median":
            return None
        return {**self.get_params(), "output": "probability"}, median_of

    def _load(self) -> Any:
        from psg_data.schemas._generator_model import load_process

        source = self.process if self.process is not None else self.dataset
        if source is None:
            raise EstimatorError(f"{self.name}: needs the generator model of a synthetic dataset (dataset=PATH of a "
                                 "psg-data synth dataset; psg-eval sets it for such datasets); other datasets have "
                                 "no exact ceiling")
        try:
            proc = load_process(source)
        except PsgDataError as exc:
            raise EstimatorError(f"{self.name}: {exc}") from None
        return proc.base_model() if self.model == "train" else proc

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> ProcessOracleEstimator:
        """Load the model and keep the training observations of every entity (``val_streams`` unused)."""
        self.validate_params()
        self.process_ = self._load()
        by_entity: dict[str, list[tuple[NDArray[np.float64], str, NDArray[np.int8]]]] = {}
        end = -np.inf
        for s in streams:
            if not isinstance(s, EdgeStream):
                raise EstimatorError(f"fit: expected EdgeStream objects, got {type(s).__name__}")
            eid, label = str(s.edge[0]), str(s.edge[1])
            if eid not in self.process_.entities:
                raise EstimatorError(f"{self.name}: edge {s.edge}: {eid!r} is not an entity of the generator model "
                                     "(is this the dataset the model belongs to?)")
            by_entity.setdefault(eid, []).append((s.t_s, label, s.y))
            if len(s):
                end = max(end, float(s.t_s[-1]))
        self.observations_: dict[str, _EntityData] = {}
        for eid, parts in by_entity.items():
            t = np.concatenate([p[0] for p in parts])
            lab = np.concatenate([np.full(p[0].size, p[1], dtype=object) for p in parts])
            y = np.concatenate([p[2] for p in parts]).astype(np.int8)
            order = np.argsort(t, kind="stable")
            self.observations_[eid] = _EntityData(t[order], lab[order], y[order])
        self.fit_end_s_ = float(end)
        self.timezone_ = timezone
        self.trackers_: dict[str, _Tracker] = {}
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> ProcessOracleFilter:
        self._check_fitted()
        eid, label = str(edge[0]), str(edge[1])
        if eid not in self.process_.entities:
            raise EstimatorError(f"{self.name}: edge {edge}: {eid!r} is not an entity of the generator model")
        empty = _EntityData(np.zeros(0), np.zeros(0, dtype=object), np.zeros(0, np.int8))
        tracker = self.trackers_.setdefault(eid, _Tracker()) if self.share_updates else None
        return ProcessOracleFilter((eid, label), self.process_, self.observations_.get(eid, empty), tracker,
                                   float(self.fit_end_s_), float(self.p_m), float(self.p_f),
                                   median=self.output == "median")

    def filter_from_state(self, state: dict[str, Any]) -> ProcessOracleFilter:
        edge = self._check_state(state)
        f = self.make_filter(edge)  # its restored observations are not re-shared with a tracker
        t = np.asarray(state.get("own_t", []), np.float64)
        y = np.asarray(state.get("own_y", []), np.int8)
        if t.size:
            f._own_t.extend(t.tolist())
            f._own_y.extend(y.tolist())
            f._own_sorted = bool(np.all(np.diff(t) >= 0))
            f._last_t = float(t[-1])
        return f


class ProcessOracleFilter(BaseFilter):
    """One edge of :class:`ProcessOracleEstimator` (exact forward algorithm, cached)."""

    def __init__(self, edge: EdgeKey, process: Any, data: _EntityData, tracker: _Tracker | None, fit_end_s: float,
                 p_m: float, p_f: float, *, median: bool = False) -> None:
        super().__init__(edge)
        self._median = median
        self._process = process
        self._entity = process.entities[edge[0]]
        self._data = data
        self._tracker = tracker
        self._fit_end = fit_end_s
        self._p_m, self._p_f = p_m, p_f
        self._own_t: list[float] = []
        self._own_y: list[int] = []
        self._own_sorted = True  # own times non-decreasing (update_many checks it; a restored state may not be)
        self._belief: Any = None
        self._belief_h: float = -np.inf
        self._seen_tracker = 0
        self._index = self._entity.state_index(edge[1])
        self._fc: list[float] | None = None  # P(state = edge's label) at steps b.n, b.n + 1, ...
        self._fc_belief: Any = None
        self._chain: list[Any] | None = None  # snapshots of the forecast belief at steps b.n, b.n + 1, ...
        self._likelihoods: dict[tuple[str, int], NDArray[np.float64]] = {}
        # with a tracker: the belief at earlier update times (time, snapshot, own and sibling-tracker
        # observations up to it), from which a sibling's late observation is absorbed again
        self._checkpoints: list[tuple[float, Any, int, int]] = []
        self._tainted = False  # the belief skipped an own observation at its own time: no checkpoint
        self._inherited = False  # the belief was handed over by a deepcopy and not used yet
        self._warm_cache: tuple[tuple[int, int, float | None], tuple[Any, float, int]] | None = None

    def __deepcopy__(self, memo: dict[int, Any]) -> ProcessOracleFilter:
        out = copy.copy(self)  # the model and the training data are read-only: shared
        out._own_t, out._own_y = list(self._own_t), list(self._own_y)
        out._tracker = copy.deepcopy(self._tracker, memo)
        out._belief = None if self._belief is None else self._belief.copy()
        out._fc, out._fc_belief, out._chain = None, None, None
        out._checkpoints = list(self._checkpoints)  # snapshots are never changed in place: shared
        out._warm_cache = None
        if self._belief is None and self._last_t is not None:  # hand the copy the belief it would compute
            warm = self._warm()
            if warm is not None:
                out._belief, out._belief_h, out._seen_tracker = warm[0].copy(), warm[1], warm[2]
                out._inherited = True
        return out

    def _warm(self) -> tuple[Any, float, int] | None:
        """The belief a copy of this filter computes at its first prediction if nothing changes before,
        computed once per state of this filter (kept for its next copies; its own belief stays unset).
        """
        key = (len(self._own_t), len(self._tracker.t) if self._tracker is not None else 0, self._last_t)
        if self._warm_cache is None or self._warm_cache[0] != key:
            tmp = copy.copy(self)
            tmp._checkpoints = []
            try:
                tmp._current()
            except EstimatorError:  # the copy meets the error itself, at its prediction
                return None
            self._warm_cache = (key, (tmp._belief, tmp._belief_h, tmp._seen_tracker))
        return self._warm_cache[1]

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        if self._belief is not None and t[0] <= self._belief_h:  # at the belief's own time: not absorbed
            if self._inherited:  # a copy's warm belief: its first prediction computes from the start
                self._belief, self._inherited = None, False
            else:
                self._tainted = True  # (until the belief is computed again from the start)
        self._own_t.extend(t.tolist())
        self._own_y.extend(int(v) for v in y)
        if self._tracker is not None:
            late = t > self._fit_end
            self._tracker.t.extend(t[late].tolist())
            self._tracker.label.extend([self.edge[1]] * int(late.sum()))
            self._tracker.y.extend(int(v) for v in y[late])

    def _own_window(self, lo: float, hi: float) -> tuple[NDArray[np.float64], NDArray[np.int8]]:
        """The own observations with lo < t <= hi, in the order they came."""
        if self._own_sorted:  # a slice: the same elements as the mask below
            a, b = bisect.bisect_right(self._own_t, lo), bisect.bisect_right(self._own_t, hi)
            return np.asarray(self._own_t[a:b], np.float64), np.asarray(self._own_y[a:b], np.int8)
        own_t = np.asarray(self._own_t, np.float64)
        m = (own_t > lo) & (own_t <= hi)
        return own_t[m], np.asarray(self._own_y, np.int8)[m]

    def _window(self, lo: float, hi: float) -> tuple[NDArray[np.float64], list[str], NDArray[np.int8]]:
        """Observations of the entity with lo < t <= hi: siblings from the training data and the
        tracker, the own edge from the filter's updates (time order; at equal times in that order).
        """
        d = self._data
        a, b = np.searchsorted(d.t, lo, side="right"), np.searchsorted(d.t, hi, side="right")
        own_t, own_y = self._own_window(lo, hi)
        tracked = self._tracker is not None and bool(self._tracker.t)
        if a == b and not tracked and self._own_sorted:  # own observations only, already in time order
            return own_t, [self.edge[1]] * own_t.size, own_y
        sib = d.label[a:b] != self.edge[1]
        ts = [d.t[a:b][sib], own_t]
        labels = list(d.label[a:b][sib]) + [self.edge[1]] * own_t.size
        ys = [d.y[a:b][sib], own_y]
        if tracked:
            tt = np.asarray(self._tracker.t, np.float64)  # type: ignore[union-attr]
            tl = np.asarray(self._tracker.label, dtype=object)  # type: ignore[union-attr]
            m = (tt > lo) & (tt <= hi) & (tl != self.edge[1])
            ts.append(tt[m])
            labels += list(tl[m])
            ys.append(np.asarray(self._tracker.y, np.int8)[m])  # type: ignore[union-attr]
        t = np.concatenate(ts)
        y = np.concatenate(ys).astype(np.int8)
        order = np.argsort(t, kind="stable")
        return t[order], [labels[i] for i in order], y[order]

    def _likelihood(self, label: str, y: int) -> NDArray[np.float64]:
        out = self._likelihoods.get((label, y))
        if out is None:
            from psg_data.synth._process import observation_likelihood

            lik = observation_likelihood(self._entity, label, y, self._p_m, self._p_f)
            out = self._likelihoods[(label, y)] = np.asarray(lik, np.float64)[None, :, None]
        return out

    def _advance(self, b: Any, n: int) -> None:
        """``b.advance_to(n)``, taking the steps the forecast chain has already computed from ``b``'s
        state (the same operations: the chain started from it and nothing was observed since).
        """
        ch = self._chain
        if ch is not None and n > b.n and ch[0][0] == b.n:
            b.restore(ch[min(n - b.n, len(ch) - 1)])
        b.advance_to(n)

    def _counts(self, tau: float) -> tuple[int, int]:
        """How many own observations, and sibling observations of the tracker, have t <= tau."""
        own = bisect.bisect_right(self._own_t, tau) if self._own_sorted else \
            int(np.count_nonzero(np.asarray(self._own_t, np.float64) <= tau))
        tr = self._tracker
        if tr is None or not tr.t:
            return own, 0
        m = (np.asarray(tr.t, np.float64) <= tau) & (np.asarray(tr.label, dtype=object) != self.edge[1])
        return own, int(np.count_nonzero(m))

    def _restart(self) -> None:
        """Go back to the latest checkpoint whose observations are all still the ones up to its time (its
        state is then the one a computation from the start reaches there), or to no belief (the start).
        """
        while self._checkpoints:
            tau, snap, own, tr = self._checkpoints[-1]
            if self._counts(tau) == (own, tr):
                self._belief.restore(snap)
                self._belief_h, self._tainted = tau, False
                self._fc, self._chain = None, None
                return
            self._checkpoints.pop()
        self._belief = None

    def _current(self) -> Any:
        """The forward belief at the step of the last update, with every allowed observation absorbed."""
        H = self._last_t
        self._inherited = False
        tracker_n = len(self._tracker.t) if self._tracker is not None else 0
        if self._belief is not None and tracker_n > self._seen_tracker:
            new_t = np.asarray(self._tracker.t[self._seen_tracker:], np.float64)  # type: ignore[union-attr]
            if np.any(new_t <= self._belief_h):  # a sibling reported an observation we have passed
                self._restart()
        self._seen_tracker = tracker_n
        if self._belief is None:
            from psg_data.synth._process import ForwardBelief

            self._belief, self._belief_h = ForwardBelief(self._process, self._entity).start(), -np.inf
            self._fc, self._chain, self._checkpoints, self._tainted = None, None, [], False
        if H is None or H <= self._belief_h:
            return self._belief
        if self._tracker is not None and not self._tainted and self._belief_h > -np.inf:
            self._checkpoints.append((self._belief_h, self._belief.snapshot(), *self._counts(self._belief_h)))
        t, labels, y = self._window(self._belief_h, H)
        b = self._belief
        try:
            steps = self._process.clock.step_of(np.append(t, H)).tolist()
            for n, lab, yy in zip(steps, labels, y.tolist()):
                self._advance(b, n)
                self._chain = None  # the belief now differs from the chain's start
                b.observe(self._likelihood(lab, yy))
            self._advance(b, steps[-1])
        except PsgDataError as exc:
            self._belief, self._checkpoints = None, []
            raise EstimatorError(f"process_oracle: edge {self.edge}: {exc}") from None
        finally:
            self._fc, self._chain = None, None
        self._belief_h = H
        return b

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._index < 0:
            return np.zeros(t.shape)
        b = self._current()
        steps = np.maximum(self._process.clock.step_of(t), b.n) - b.n
        if self._fc is None:
            self._fc_belief = b.copy()
            self._fc, self._chain = [float(b.state_marginal()[self._index])], [self._fc_belief.snapshot()]
        fc, chain = self._fc, self._chain
        assert chain is not None
        while len(fc) <= int(steps.max(initial=0)):  # extend the cached forecast to the furthest step
            self._fc_belief.advance()
            chain.append(self._fc_belief.snapshot())
            fc.append(float(self._fc_belief.state_marginal()[self._index]))
        p = np.asarray(fc)[steps]
        return median_of(p) if self._median else p

    def get_state(self) -> dict[str, Any]:
        return {"estimator": ProcessOracleEstimator.name, "edge": [self.edge[0], self.edge[1]],
                "own_t": list(self._own_t), "own_y": list(self._own_y)}
