"""Aggregation over seeds/scenes: mean, std, bootstrap CI, counts."""

from __future__ import annotations

import json
import statistics

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EvaluationError
from psg_data.evaluation import Summary, bootstrap_ci, summarize


def test_summary_mean_std_with_ddof():
    v = [0.61, 0.66, 0.7, 0.64, 0.69]
    s = summarize(v)
    assert s.n == 5
    assert s.mean == pytest.approx(statistics.fmean(v))
    assert s.std == pytest.approx(statistics.stdev(v))
    assert summarize(v, ddof=0).std == pytest.approx(statistics.pstdev(v))
    assert s.ci_low <= s.mean <= s.ci_high
    assert min(v) <= s.ci_low and s.ci_high <= max(v)


def test_single_value_and_empty_and_nan():
    s = summarize([0.42])
    assert (s.mean, s.std, s.ci_low, s.ci_high, s.n) == (0.42, 0.0, 0.42, 0.42, 1)
    e = summarize([])
    assert e.n == 0 and np.isnan(e.mean) and np.isnan(e.std)
    assert e.to_dict() == {"mean": None, "std": None, "ci_low": None, "ci_high": None, "n": 0, "method": "percentile",
                           "unit": "values"}
    json.dumps(e.to_dict(), allow_nan=False)
    s2 = summarize([0.2, np.nan, 0.4])
    assert s2.n == 2 and s2.mean == pytest.approx(0.3)
    with pytest.raises(EvaluationError, match="infinite"):
        summarize([1.0, np.inf])


def test_bootstrap_two_point_distribution_by_hand():
    # resampled means of [0, 1] are 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4
    assert bootstrap_ci([0.0, 1.0], confidence=0.95, n_bootstrap=4000, seed=1) == (0.0, 1.0)
    assert bootstrap_ci([0.0, 1.0], confidence=0.4, n_bootstrap=4000, seed=1) == (0.5, 0.5)


def test_bootstrap_is_deterministic_with_a_seed():
    v = np.random.default_rng(3).normal(size=30)
    assert bootstrap_ci(v, seed=7) == bootstrap_ci(v, seed=7)
    assert summarize(v, seed=7) == summarize(v, seed=7)
    assert bootstrap_ci(v, seed=7) != bootstrap_ci(v, seed=8)
    with pytest.raises(EvaluationError, match="confidence must be in"):
        bootstrap_ci(v, confidence=1.5)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=30), st.integers(0, 2**32 - 1))
def test_bootstrap_ci_contains_the_mean(values, seed):
    s = summarize(values, seed=seed, n_bootstrap=500)
    tol = 1e-9 * (1 + abs(s.mean))
    assert s.ci_low - tol <= s.mean <= s.ci_high + tol
    assert s.ci_low <= s.ci_high
    assert isinstance(s, Summary)
