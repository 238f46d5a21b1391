"""segment_stream as it was at main aaa7199 (kept as the reference of tests/estimators/test_segmentation_fast.py)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


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
