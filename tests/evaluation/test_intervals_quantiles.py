"""The intervals' t and normal quantiles are scipy.stats' numbers to the last bit, without importing
scipy.stats (psg-eval's serial part after the pool paid 1-3 s for that import)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from psg_data.evaluation._intervals import _bootstrap_level, _t_ppf


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.floats(1e-6, 1 - 1e-6), st.integers(1, 500))
def test_t_quantile_is_scipy_stats_bit_for_bit(q: float, df: int) -> None:
    want = float(stats.t.ppf(q, df))
    assert _t_ppf(q, df) == want


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.integers(2, 400), st.sampled_from([0.5, 0.8, 0.9, 0.95, 0.99, 0.999]))
def test_bootstrap_level_is_the_scipy_stats_formula_bit_for_bit(n: int, conf: float) -> None:
    want = float(stats.norm.cdf(math.sqrt(n / (n - 1)) * stats.t.ppf((1.0 - conf) / 2.0, n - 1)))
    assert _bootstrap_level(n, conf) == want


def test_intervals_do_not_import_scipy_stats() -> None:
    code = ("import sys; from psg_data.evaluation._intervals import cluster_bootstrap, cluster_jackknife, t_interval;"
            "import numpy as np; r = np.random.default_rng(0);"
            "cluster_bootstrap(r.random(12), r.random(12) + 1); cluster_jackknife(r.random(5), r.random(5) + 1);"
            "t_interval(r.random(4)); print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_intervals_equal_the_scipy_stats_formulas() -> None:
    from psg_data.evaluation._intervals import cluster_bootstrap, cluster_jackknife, t_interval

    r = np.random.default_rng(3)
    v = r.random(6)
    half = float(stats.t.ppf(0.975, 5) * np.std(v, ddof=1) / math.sqrt(6))
    iv = t_interval(v)
    assert (iv.low, iv.high) == (float(np.mean(v)) - half, float(np.mean(v)) + half)
    num, den = r.random(7), r.random(7) + 1
    jk = cluster_jackknife(num, den)
    loo = (num.sum() - num) / (den.sum() - den)
    se = math.sqrt(6 / 7 * float(np.sum((loo - loo.mean()) ** 2)))
    est = float(num.sum() / den.sum())
    h = float(stats.t.ppf(0.975, 6)) * se
    assert (jk.low, jk.high) == (est - h, est + h)
    num, den = r.random(15), r.random(15) + 1
    bs = cluster_bootstrap(num, den, n_bootstrap=500, seed=2)
    counts = np.random.default_rng(2).multinomial(15, np.full(15, 1 / 15), size=500).astype(np.float64)
    stat = (counts @ num) / (counts @ den)
    a = float(stats.norm.cdf(math.sqrt(15 / 14) * stats.t.ppf(0.025, 14)))
    assert (bs.low, bs.high) == tuple(float(x) for x in np.nanquantile(stat, [a, 1.0 - a]))
