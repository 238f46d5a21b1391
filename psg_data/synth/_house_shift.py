"""Is the test-time shift real? A chi-square test of observed transitions against a model.

:func:`transition_test` asks whether the transitions of state paths inside a step window (the
test week) follow a given model (the training model). Under the model, the next state given the
path so far is distributed as the exact one-step predictive ``p_n = P(s_n | s_0 .. s_{n-1})``
(the forward algorithm with every earlier state observed). Transitions are grouped into bins
``(entity, previous state, block of hours)`` (``block_hours``, default 24: one block; the
predictive already depends on the hour, and 6-hour blocks left too few transitions per bin for the
chi-square approximation: under the null their p-values were erratic, 0.008 to 0.99 on three
weeks of unshifted houses); per bin, ``O`` counts the next
states, ``E = sum_n p_n`` and ``V = sum_n (diag p_n - p_n p_n^T)``. ``O - E`` is a sum of
martingale differences with covariance ``V``, so ``T = sum_bins (O - E)^T V^+ (O - E)`` is
asymptotically chi-square with ``sum rank V`` degrees of freedom under the model (a generalised
Pearson statistic; entities are independent, and bins of one entity are uncorrelated because each
step adds to one bin only). A transition the model gives probability 0 makes the p-value 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import PsgDataError
from psg_data.schemas._generator_model import StepProcess

__all__ = ["TransitionTest", "transition_test"]


@dataclass(frozen=True)
class TransitionTest:
    """Result of :func:`transition_test`.

    Attributes:
        statistic: the generalised Pearson statistic T (inf with an impossible transition).
        df: degrees of freedom (sum of the bins' covariance ranks).
        p_value: P(chi2_df >= T) (0 with an impossible transition).
        n_transitions: transitions tested.
        n_impossible: transitions the model gives probability 0.
        entities: entities tested.
    """

    statistic: float
    df: int
    p_value: float
    n_transitions: int
    n_impossible: int
    entities: int


def _entity_bins(process: StepProcess, item: int, eid: str, states: NDArray[np.int64], lo: int, hi: int,
                 block_hours: int, acc: dict[tuple, list[NDArray[np.float64]]]) -> tuple[int, int]:
    from psg_data.synth._process import ForwardBelief

    e = process.entities[eid]
    S = e.n_states
    b = ForwardBelief(process, e).start()
    n_tr = 0
    for n in range(min(hi, len(states))):
        if n:
            b.advance()
        p = b.state_marginal()
        s = int(states[n])
        if n >= max(lo, 1):
            if p[s] <= 0.0:
                return n_tr, 1
            hour = int(process.step_hours[n % process.n_slots]) // block_hours
            key = (item, eid, int(states[n - 1]), hour)
            o, ex, v = acc.setdefault(key, [np.zeros(S), np.zeros(S), np.zeros((S, S))])
            o[s] += 1.0
            ex += p
            v += np.diag(p) - np.outer(p, p)
            n_tr += 1
        try:
            b.observe(np.eye(S)[s])
        except PsgDataError:
            return n_tr, 1
    return n_tr, 0


def transition_test(items: Iterable[tuple[StepProcess, Mapping[str, Sequence[int] | NDArray[np.int64]]]],
                    first_step: int, end_step: int, *, block_hours: int = 24) -> TransitionTest:
    """Test the transitions of paths in steps ``[first_step, end_step)`` against a model (module docstring).

    Args:
        items: ``(model, {entity_id: state index per step from step 0})`` pairs (e.g. one per house:
            its training model and the sampled paths of its moving objects).
        first_step: first step of the tested window (the transition into step n is tested for n in it).
        end_step: end of the window (exclusive).
        block_hours: hours per time-of-day block of the bins.
    """
    from scipy.stats import chi2

    acc: dict[tuple, list[NDArray[np.float64]]] = {}
    n_tr = n_bad = n_ent = 0
    for k, (process, paths) in enumerate(items):
        for eid, states in paths.items():
            t, bad = _entity_bins(process, k, eid, np.asarray(states, np.int64), first_step, end_step, block_hours,
                                  acc)
            n_tr, n_bad, n_ent = n_tr + t, n_bad + bad, n_ent + 1
    if n_bad:
        return TransitionTest(math.inf, 0, 0.0, n_tr, n_bad, n_ent)
    stat, df = 0.0, 0
    for o, ex, v in acc.values():
        w, U = np.linalg.eigh(v)
        keep = w > 1e-9 * max(1.0, float(w.max(initial=0.0)))
        z = U[:, keep].T @ (o - ex)
        stat += float(np.sum(z * z / w[keep]))
        df += int(keep.sum())
    p = float(chi2.sf(stat, df)) if df else 1.0
    return TransitionTest(stat, df, p, n_tr, 0, n_ent)

