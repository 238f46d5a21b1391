"""Reference copy of ``process_oracle``'s filter and forward algorithm as of main 8f53f6f (issue 45), kept unchanged.

``ProcessOracleFilter`` (psg_data/estimators/_process_oracle.py) and ``ForwardBelief`` /
``observation_likelihood`` (psg_data/synth/_process.py) before they were made cheap (cached kernel
constants, the forecast chain reused by the filter, fewer numpy calls per step). The tests compare
the package's filters with these on the demo's edges, a navigation benchmark scene and random
inputs. Do not edit except to follow API renames.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError, PsgDataError
from psg_data.estimators._base import EdgeKey
from psg_data.estimators._common import BaseFilter
from psg_data.estimators._process_oracle import _EntityData, _Tracker
from psg_data.schemas._generator_model import EntityProcess, StepProcess

__all__ = ["ForwardBelief", "observation_likelihood", "ProcessOracleFilter", "reference_filter"]


class ForwardBelief:
    """Exact filtering and forecasting for one entity: the belief over (pattern, state, dwell).

    ``alpha[p, s, r - 1]`` is P(pattern p on the current day, state s, remaining dwell r | the
    observations absorbed so far) at step ``n``. Start with :meth:`start` (the belief at step 0),
    absorb observations with :meth:`observe`, move on with :meth:`advance_to`.
    """

    def __init__(self, process: StepProcess, entity: EntityProcess) -> None:
        self.process = process
        self.entity = entity
        self._base = entity
        self.U = entity.dwell_pmf()
        self.n = -1
        self.alpha = np.zeros((entity.n_patterns, entity.n_states, entity.max_dwell))
        self.log_evidence = 0.0

    def copy(self) -> ForwardBelief:
        """An independent copy of the belief (same process, own state)."""
        out = ForwardBelief.__new__(ForwardBelief)
        out.process, out.entity, out.U, out._base = self.process, self.entity, self.U, self._base
        out.n, out.alpha, out.log_evidence = self.n, self.alpha.copy(), self.log_evidence
        return out

    def start(self) -> ForwardBelief:
        """The belief at step 0 (no observation)."""
        e = self.entity
        pre = np.zeros_like(self.alpha)
        pre[:, :, 0] = self.process.day_initial(e)[:, None] * e.state_initial[None, :]
        self.alpha = self._hour_kernel(pre, 0)
        self.n = 0
        return self

    def _hour_kernel(self, beta: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        e = self.entity
        rho = e.routine_strength[:, k][:, None, None]
        tot = beta.sum(axis=(1, 2))
        routine = np.zeros_like(beta)
        idx = np.arange(e.n_patterns)
        routine[idx, e.routine[:, k], :] = tot[:, None] * self.U[idx, e.routine[:, k], :]
        hold = np.zeros_like(beta)
        hold[:, :, :-1] = beta[:, :, 1:]
        jumped = np.einsum("ps,pst->pt", beta[:, :, 0], e.jump)
        return rho * routine + (1.0 - rho) * (hold + jumped[:, :, None] * self.U)

    def advance(self) -> None:
        """Move the belief one step ahead (no observation); at a regime's first day the regime's model
        of the entity takes over.
        """
        n = self.n + 1
        day, k = divmod(n, self.process.n_slots)
        beta = self.alpha
        if k == 0:
            if self.process.regimes:
                e = self.process.entity_on(self._base.entity_id, day, self._base)
                if e is not self.entity:
                    self.entity, self.U = e, e.dwell_pmf()
            beta = np.einsum("psr,pq->qsr", beta, self.process.day_matrix(self.entity, day))
        self.alpha = self._hour_kernel(beta, k)
        self.n = n

    def advance_to(self, n: int) -> None:
        """Advance the belief to step ``n`` without observations.

        Raises:
            PsgDataError: ``n`` is before the current step.
        """
        if n < self.n:
            raise PsgDataError(f"ForwardBelief: cannot go back from step {self.n} to {n}")
        while self.n < n:
            self.advance()

    def observe(self, likelihood: NDArray[np.float64]) -> None:
        """Absorb an observation at the current step given its likelihood per state, (S,).

        Raises:
            PsgDataError: the observation is impossible under the model (zero evidence).
        """
        a = self.alpha * np.asarray(likelihood, np.float64)[None, :, None]
        z = float(a.sum())
        if not z > 0.0:
            raise PsgDataError(f"{self.entity.entity_id}: observation at step {self.n} is impossible under the "
                               "generator model (zero likelihood); noisy labels need p_m/p_f > 0")
        self.alpha = a / z
        self.log_evidence += math.log(z)

    def state_marginal(self) -> NDArray[np.float64]:
        """(S,) P(state) at the current step."""
        return self.alpha.sum(axis=(0, 2))

    def forecast(self, steps: Sequence[int] | NDArray[np.int64]) -> NDArray[np.float64]:
        """(len(steps), S) state marginals at future steps (>= the current one), without changing the belief."""
        steps = np.asarray(steps, np.int64)
        out = np.zeros((steps.size, self.entity.n_states))
        if steps.size == 0:
            return out
        order = np.argsort(steps, kind="stable")
        b = self.copy()
        for i in order:
            b.advance_to(int(max(steps[i], self.n)))
            out[i] = b.state_marginal()
        return out


def observation_likelihood(entity: EntityProcess, label: str | None, y: int, p_m: float, p_f: float
                           ) -> NDArray[np.float64]:
    """(S,) P(y | state) of an edge observation: edge ``(entity, label)`` seen present (1) or absent (0).

    P(y=1 | at label) = 1 - p_m, P(y=1 | elsewhere) = p_f; a label the entity never takes gives
    P(y=1) = p_f in every state.
    """
    j = entity.state_index(label)
    at = np.zeros(entity.n_states, bool)
    if j >= 0:
        at[j] = True
    p1 = np.where(at, 1.0 - p_m, p_f)
    return p1 if int(y) == 1 else 1.0 - p1


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
        self._belief: Any = None
        self._belief_h: float = -np.inf
        self._seen_tracker = 0
        self._index = self._entity.state_index(edge[1])
        self._fc: list[NDArray[np.float64]] | None = None  # state marginals at steps b.n, b.n + 1, ...
        self._fc_belief: Any = None

    def __deepcopy__(self, memo: dict[int, Any]) -> ProcessOracleFilter:
        out = copy.copy(self)  # the model and the training data are read-only: shared
        out._own_t, out._own_y = list(self._own_t), list(self._own_y)
        out._tracker = copy.deepcopy(self._tracker, memo)
        out._belief = None if self._belief is None else self._belief.copy()
        out._fc, out._fc_belief = None, None
        return out

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        self._own_t.extend(t.tolist())
        self._own_y.extend(int(v) for v in y)
        if self._tracker is not None:
            late = t > self._fit_end
            self._tracker.t.extend(t[late].tolist())
            self._tracker.label.extend([self.edge[1]] * int(late.sum()))
            self._tracker.y.extend(int(v) for v in y[late])

    def _window(self, lo: float, hi: float) -> tuple[NDArray[np.float64], list[str], NDArray[np.int8]]:
        """Observations of the entity with lo < t <= hi: siblings from the training data and the
        tracker, the own edge from the filter's updates.
        """
        d = self._data
        a, b = np.searchsorted(d.t, lo, side="right"), np.searchsorted(d.t, hi, side="right")
        sib = d.label[a:b] != self.edge[1]
        ts = [d.t[a:b][sib]]
        labels = list(d.label[a:b][sib])
        ys = [d.y[a:b][sib]]
        own_t = np.asarray(self._own_t, np.float64)
        m = (own_t > lo) & (own_t <= hi)
        ts.append(own_t[m])
        labels += [self.edge[1]] * int(m.sum())
        ys.append(np.asarray(self._own_y, np.int8)[m])
        if self._tracker is not None and self._tracker.t:
            tt = np.asarray(self._tracker.t, np.float64)
            tl = np.asarray(self._tracker.label, dtype=object)
            m = (tt > lo) & (tt <= hi) & (tl != self.edge[1])
            ts.append(tt[m])
            labels += list(tl[m])
            ys.append(np.asarray(self._tracker.y, np.int8)[m])
        t = np.concatenate(ts)
        y = np.concatenate(ys).astype(np.int8)
        order = np.argsort(t, kind="stable")
        return t[order], [labels[i] for i in order], y[order]

    def _current(self) -> Any:
        """The forward belief at the step of the last update, with every allowed observation absorbed."""
        H = self._last_t
        tracker_n = len(self._tracker.t) if self._tracker is not None else 0
        if self._belief is not None and tracker_n > self._seen_tracker:
            new_t = np.asarray(self._tracker.t[self._seen_tracker:], np.float64)  # type: ignore[union-attr]
            if np.any(new_t <= self._belief_h):  # a sibling reported an observation we have passed
                self._belief = None
        self._seen_tracker = tracker_n
        if self._belief is None:
            self._belief, self._belief_h = ForwardBelief(self._process, self._entity).start(), -np.inf
            self._fc = None
        if H is None or H <= self._belief_h:
            return self._belief
        self._fc = None
        t, labels, y = self._window(self._belief_h, H)
        b = self._belief
        try:
            steps = self._process.clock.step_of(t)
            for n, lab, yy in zip(steps, labels, y):
                b.advance_to(int(n))
                b.observe(observation_likelihood(self._entity, lab, int(yy), self._p_m, self._p_f))
            b.advance_to(int(self._process.clock.step_of(np.array([H]))[0]))
        except PsgDataError as exc:
            self._belief = None
            raise EstimatorError(f"process_oracle: edge {self.edge}: {exc}") from None
        self._belief_h = H
        return b

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._index < 0:
            return np.zeros(t.shape)
        b = self._current()
        steps = np.maximum(self._process.clock.step_of(t), b.n) - b.n
        if self._fc is None:
            self._fc, self._fc_belief = [b.state_marginal()], b.copy()
        while len(self._fc) <= int(steps.max(initial=0)):  # extend the cached forecast to the furthest step
            self._fc_belief.advance()
            self._fc.append(self._fc_belief.state_marginal())
        p = np.asarray(self._fc)[steps, self._index]
        return (p >= 0.5).astype(np.float64) if self._median else p

    def get_state(self) -> dict[str, Any]:
        return {"estimator": "process_oracle", "edge": [self.edge[0], self.edge[1]],
                "own_t": list(self._own_t), "own_y": list(self._own_y)}


def reference_filter(estimator: Any, edge: EdgeKey) -> ProcessOracleFilter:
    """The reference filter of ``edge`` built from a fitted ``ProcessOracleEstimator`` as its ``make_filter`` does."""
    new = estimator.make_filter(edge)
    return ProcessOracleFilter(new.edge, estimator.process_, new._data, new._tracker, float(estimator.fit_end_s_),
                               float(estimator.p_m), float(estimator.p_f), median=estimator.output == "median")
