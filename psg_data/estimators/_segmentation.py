"""Change-point segmentations of 0/1 observation streams (training sequences for the mixtures).

- :func:`segment_stream`: exact PELT with a Bernoulli cost, every index a candidate, minimum
  segment ``min_size`` observations, penalty in nats (psg-data's earlier default, named
  ``"bernoulli"``);
- :func:`segment_reference`: what the public Perpetua reference *actually* runs. It passes its own
  Bernoulli cost to ruptures' ``Pelt(custom_cost=...)``, but the class does not subclass ruptures'
  ``BaseCost``, so ruptures silently uses its default L2 cost with ``min_size=2``, ``jump=5`` and
  penalty 3. This function reproduces ruptures' ``Pelt(model="l2", min_size=2, jump=5)
  .fit(y).predict(pen=3)`` exactly (same candidate grid, same pruning rule, same tie-breaking),
  without the dependency (tested against ruptures).

Both return segment boundaries ``b`` (``b[0] = 0``, ``b[-1] = N``; segment j is ``y[b[j]:b[j+1]]``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["segment_stream", "segment_reference", "segment_labels"]


_TINY = 1e-300
_SCALAR_UP_TO = 24  # eligible candidates scored in plain floats up to this many, as one numpy pass above

Costs = tuple[int, float, list[bool]]


def _costs_numpy(e: float, cse: float, cc: list[float], ccs: list[float], cf: list[float], penalty: float) -> Costs:
    """(argmin, best cost, which candidates survive PELT's pruning) of segments ending at ``e``."""
    c, csc, fc = np.array(cc), np.array(ccs), np.array(cf)
    k = cse - csc
    nn = e - c
    p = k / nn
    # the floor leaves log(p) alone for p >= 1/n and makes 0 * log(0) a 0
    nll = k * np.log(np.maximum(p, _TINY)) + (nn - k) * np.log(np.maximum(1 - p, _TINY))
    cost = (fc - nll) + penalty
    j = int(np.argmin(cost))
    fe = float(cost[j])
    return j, fe, ((cost - penalty) <= fe).tolist()


def _costs_scalar(e: float, cse: float, cc: list[float], ccs: list[float], cf: list[float], penalty: float) -> Costs:
    """:func:`_costs_numpy` operation for operation in Python floats (no per-call numpy cost)."""
    log = math.log
    fe, j, costs = math.inf, 0, []
    for i in range(len(cc)):
        k = cse - ccs[i]
        nn = e - cc[i]
        p = k / nn
        nll = k * log(max(p, _TINY)) + (nn - k) * log(max(1 - p, _TINY))
        cost = (cf[i] - nll) + penalty
        costs.append(cost)
        if cost < fe:
            fe, j = cost, i
    return j, fe, [(x - penalty) <= fe for x in costs]


def _middle_of_three(cc: list[float], ccs: list[float], cf: list[float], i: int) -> bool:
    """Candidates i-2 < i-1 < i with one best cost and one value everywhere between them: once i is
    eligible, i-1 never wins again (while the segment from i stays pure the three cost the same and the
    earliest wins; once it is not, the later candidate costs strictly less) and never decides a pruning.
    """
    d = ccs[i] - ccs[i - 2]
    return cf[i - 2] == cf[i - 1] == cf[i] and (d == 0.0 or d == cc[i] - cc[i - 2])


def segment_stream(y: ArrayLike, *, min_size: int = 5, penalty: float = 3.0) -> NDArray[np.int64]:
    """Optimal partition of a 0/1 sequence (PELT, Bernoulli cost, every index a candidate).

    The cost of a segment with k ones out of n is ``-(k log(k/n) + (n-k) log(1 - k/n))`` (0 log 0 = 0);
    a candidate is pruned when its cost without the penalty exceeds the best cost (PELT); ties go to
    the earliest candidate. The boundaries are those of main aaa7199's version (kept in
    tests/estimators/_segmentation_reference.py), which kept every index of a pure run as a
    candidate; here the middle one of three equal candidates is dropped (:func:`_middle_of_three`)
    and a few candidates are scored without numpy.
    """
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    n = y.size
    if n < 2 * min_size:
        return np.array([0, n], dtype=np.int64)
    cs = np.concatenate([[0.0], np.cumsum(y)]).tolist()
    last = [0] * (n + 1)
    cc, ccs, cf = [0.0], [0.0], [-penalty]  # live candidates, ascending: index, cs there, best cost up to there
    m = 0  # how many of them are eligible (at least min_size before the end)
    for e in range(min_size, n + 1):
        while m < len(cc) and cc[m] <= e - min_size:
            if m >= 2 and _middle_of_three(cc, ccs, cf, m):
                del cc[m - 1], ccs[m - 1], cf[m - 1]
            else:
                m += 1
        if m == 0:
            continue
        costs = _costs_scalar if m <= _SCALAR_UP_TO else _costs_numpy
        j, fe, keep = costs(float(e), cs[e], cc[:m], ccs[:m], cf[:m], penalty)
        last[e] = int(cc[j])
        for col in (cc, ccs, cf):
            col[:m] = [x for x, k in zip(col[:m], keep) if k]
        m = sum(keep)
        cc.append(float(e))
        ccs.append(cs[e])
        cf.append(fe)
    b = [n]
    while b[-1] > 0:
        b.append(last[b[-1]])
    return np.array(b[::-1], dtype=np.int64)


def segment_reference(y: ArrayLike, *, penalty: float = 3.0, min_size: int = 2, jump: int = 5) -> NDArray[np.int64]:
    """Ruptures' PELT with the L2 cost, as the Perpetua reference runs it (see the module docstring).

    Candidate change points are the multiples of ``jump`` that leave ``min_size`` samples on the
    left, plus N; the L2 cost of ``y[s:e]`` is ``sum (y - mean)^2`` (for 0/1 data ``k (n - k) / n``
    with k ones); a candidate is pruned when its partial cost exceeds the best by more than the
    penalty; ties go to the earliest candidate.
    """
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    n = y.size
    if n < 2 * min_size or n < 2:
        return np.array([0, n], dtype=np.int64)
    s1 = np.concatenate([[0.0], np.cumsum(y)])
    s2 = np.concatenate([[0.0], np.cumsum(y * y)])
    total = np.full(n + 1, np.nan)
    total[0] = 0.0
    back = np.zeros(n + 1, dtype=np.int64)
    adm = np.zeros(0, dtype=np.int64)
    ind = [k for k in range(0, n, jump) if k >= min_size] + [n]
    for bkp in ind:
        adm = np.append(adm, int(math.floor((bkp - min_size) / jump)) * jump)
        adm = adm[~np.isnan(total[adm])]
        m = (bkp - adm).astype(np.float64)
        c = np.maximum(s2[bkp] - s2[adm] - (s1[bkp] - s1[adm]) ** 2 / m, 0.0)
        v = total[adm] + (c + penalty)
        j = int(np.argmin(v))
        total[bkp] = v[j]
        back[bkp] = adm[j]
        adm = adm[v <= v[j] + penalty]
    b = [n]
    while b[-1] > 0:
        b.append(back[b[-1]])
    return np.array(b[::-1], dtype=np.int64)


def segment_labels(y: ArrayLike, bounds: NDArray[np.int64]) -> NDArray[np.int8]:
    """(N,) per-observation majority label (>= 0.5 counts as present) of each segment."""
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    lab = [int(y[a:b].mean() >= 0.5) if b > a else 0 for a, b in zip(bounds[:-1], bounds[1:])]
    return np.repeat(np.array(lab, dtype=np.int8), np.diff(bounds)).astype(np.int8)
