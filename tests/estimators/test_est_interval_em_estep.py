"""The log-normal E-step (which skips the exact-row branch when a batch has no exact row and tests
finiteness once) equals the per-problem original kept in _interval_em_reference.py bit for bit: rows
with and without exact durations, left-open (lo = 0), right-censored (hi = inf) and narrow intervals."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators._interval_em import _estep_lognormal
from tests.estimators import _interval_em_reference as ref


def _rows(seed: int, n: int, exact_share: float) -> tuple[np.ndarray, np.ndarray]:
    r = np.random.default_rng(seed)
    lo = np.exp(r.uniform(2.0, 13.0, n))
    hi = lo * np.exp(r.uniform(0.0, 3.0, n))
    kind = r.random(n)
    lo = np.where(kind < 0.3, 0.0, lo)  # still present at the first scan: (0, hi]
    hi = np.where((kind >= 0.3) & (kind < 0.4), np.inf, hi)  # right-censored
    hi = np.where((kind >= 0.4) & (kind < 0.5), lo * (1.0 + r.uniform(1e-12, 1e-6, n)), hi)  # narrow
    exact = (r.random(n) < exact_share) & (lo > 0)
    return lo, np.where(exact, lo, hi)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.integers(0, 100_000), st.integers(1, 60), st.integers(1, 5), st.sampled_from([0.0, 0.0, 0.2, 1.0]))
def test_lognormal_estep_equals_the_original_bit_for_bit(seed: int, n: int, k: int, exact_share: float) -> None:
    lo, hi = _rows(seed, n, exact_share)
    r = np.random.default_rng(seed + 1)
    mu = r.uniform(3.0, 12.0, k)
    sd = r.uniform(0.05, 3.0, k)
    got = _estep_lognormal(lo, hi, mu, sd)
    with np.errstate(all="ignore"):
        want = ref._estep_lognormal(lo, hi, mu, sd)
    for g, w in zip(got, want):
        assert g.shape == w.shape
        assert np.array_equal(g, w, equal_nan=True)
