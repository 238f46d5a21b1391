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


def _bern_cost(k: NDArray[np.float64], n: NDArray[np.float64]) -> NDArray[np.float64]:
    """-max log-likelihood of a Bernoulli segment with k ones out of n."""
    with np.errstate(divide="ignore", invalid="ignore"):
        p = k / n
        a = np.where(k > 0, k * np.log(np.where(k > 0, p, 1.0)), 0.0)
        b = np.where(n - k > 0, (n - k) * np.log(np.where(n - k > 0, 1 - p, 1.0)), 0.0)
    return -(a + b)


def segment_stream(y: ArrayLike, *, min_size: int = 5, penalty: float = 3.0) -> NDArray[np.int64]:
    """Optimal partition of a 0/1 sequence (PELT, Bernoulli cost, every index a candidate)."""
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    n = y.size
    if n < 2 * min_size:
        return np.array([0, n], dtype=np.int64)
    cs = np.concatenate([[0.0], np.cumsum(y)])
    f = np.full(n + 1, np.inf)
    f[0] = -penalty
    last = np.zeros(n + 1, dtype=np.int64)
    cands = np.array([0], dtype=np.int64)
    for e in range(min_size, n + 1):
        elig = cands <= e - min_size
        c = cands[elig]
        if c.size == 0:
            continue
        cost = f[c] + _bern_cost(cs[e] - cs[c], (e - c).astype(np.float64)) + penalty
        j = int(np.argmin(cost))
        f[e] = cost[j]
        last[e] = c[j]
        prune = np.zeros(cands.size, dtype=bool)
        prune[elig] = (cost - penalty) > f[e]
        cands = np.append(cands[~prune], e)
    b = [n]
    while b[-1] > 0:
        b.append(int(last[b[-1]]))
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
