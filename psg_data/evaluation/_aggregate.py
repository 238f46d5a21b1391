"""Aggregation across scenes or seeds: mean, standard deviation, a confidence interval and the count.

:class:`Summary` is the record every table cell comes from; its interval's meaning is in
``method`` / ``unit`` (see :mod:`psg_data.evaluation._intervals` for the intervals the harnesses use).
:func:`summarize` is the plain helper for a list of values:

- ``std`` uses ``ddof=1`` (sample standard deviation) by default; with a single value (n=1) the
  standard deviation is reported as 0.0 (not NaN) and the CI collapses to that value. ``n`` is
  always reported beside the numbers so a reader can tell.
- Confidence intervals are percentile bootstrap intervals of the mean, resampling the values with
  replacement ``n_bootstrap`` times using ``numpy.random.default_rng(seed)``: deterministic for a
  given seed.
- NaN values (runs that could not be scored) are dropped before aggregation; ``n`` counts the
  values kept. With nothing left every number is NaN and ``n == 0``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from psg_data.errors import EvaluationError

__all__ = ["Summary", "summarize", "bootstrap_ci"]


@dataclass(frozen=True)
class Summary:
    """Mean, spread and count of one metric over scenes or seeds.

    Attributes:
        mean: the point estimate (mean of the values).
        std: standard deviation across seeds or draws with ddof=1 (0.0 when there is one).
        ci_low: lower end of the confidence interval.
        ci_high: upper end of it.
        n: number of resampled units (values, objects, draws, queries).
        method: how the interval was made (``bootstrap``, ``t``, ``jackknife-t``, ``percentile``
            for :func:`summarize`, ``none``).
        unit: the resampled unit (``objects``, ``lab draws``, ``queries``, ``values``).
    """

    mean: float
    std: float
    ci_low: float
    ci_high: float
    n: int
    method: str = "percentile"
    unit: str = "values"

    @property
    def half_width(self) -> float:
        """Half the interval's width (what the tables print after ``±``); NaN without an interval."""
        return (self.ci_high - self.ci_low) / 2.0 if math.isfinite(self.ci_low) and math.isfinite(self.ci_high) \
            else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict; NaN becomes None."""
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(self).items()}

    def __str__(self) -> str:
        hw = self.half_width
        return f"{self.mean:.3f} ± {hw:.3f} (n={self.n})" if math.isfinite(hw) else f"{self.mean:.3f} (n={self.n})"

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Summary:
        """The object a :meth:`to_dict` dict describes."""
        nan = float("nan")
        f = lambda k: nan if d.get(k) is None else float(d[k])  # noqa: E731
        return Summary(f("mean"), f("std"), f("ci_low"), f("ci_high"), int(d.get("n") or 0),
                       str(d.get("method", "percentile")), str(d.get("unit", "values")))


def bootstrap_ci(
    values: ArrayLike,
    *,
    confidence: float = 0.95,
    n_bootstrap: int = 2000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of the mean.

    Args:
        values: (n,) finite values.
        confidence: coverage in (0, 1).
        n_bootstrap: number of resamples.
        seed: seed of ``numpy.random.default_rng``.

    Returns:
        ``(low, high)``; ``(v, v)`` for a single value, NaNs for none.

    Example:
        >>> bootstrap_ci([1.0, 1.0, 1.0])
        (1.0, 1.0)
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if not 0.0 < confidence < 1.0:
        raise EvaluationError(f"confidence must be in (0, 1), got {confidence}")
    if n_bootstrap < 1:
        raise EvaluationError(f"n_bootstrap must be >= 1, got {n_bootstrap}")
    if not np.all(np.isfinite(v)):
        raise EvaluationError("bootstrap_ci: values must be finite (drop NaN first)")
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size == 1 or np.all(v == v[0]):
        return float(v[0]), float(v[0])
    rng = np.random.default_rng(seed)
    means = np.empty(n_bootstrap, dtype=np.float64)
    chunk = max(1, 2_000_000 // v.size)  # bound memory: at most ~2e6 resampled values at once
    for start in range(0, n_bootstrap, chunk):
        stop = min(n_bootstrap, start + chunk)
        idx = rng.integers(0, v.size, size=(stop - start, v.size))
        means[start:stop] = v[idx].mean(axis=1)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [alpha, 1.0 - alpha])
    return float(low), float(high)


def summarize(
    values: ArrayLike,
    *,
    ddof: int = 1,
    confidence: float = 0.95,
    n_bootstrap: int = 2000,
    seed: int = 0,
) -> Summary:
    """Mean, standard deviation, bootstrap CI of the mean and count of ``values``.

    Args:
        values: (n,) per-scene or per-seed values; NaN entries are dropped.
        ddof: delta degrees of freedom of the standard deviation (default 1). When
            ``n <= ddof`` the standard deviation is 0.0.
        confidence: CI coverage.
        n_bootstrap: bootstrap resamples.
        seed: bootstrap seed (deterministic).

    Returns:
        A :class:`Summary`.

    Example:
        >>> s = summarize([0.5, 0.7])
        >>> (round(s.mean, 3), round(s.std, 4), s.n)
        (0.6, 0.1414, 2)
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[~np.isnan(v)]
    if np.any(np.isinf(v)):
        raise EvaluationError("summarize: values must not be infinite")
    n = int(v.size)
    if n == 0:
        nan = float("nan")
        return Summary(nan, nan, nan, nan, 0)
    mean = float(np.mean(v))
    std = float(np.std(v, ddof=ddof)) if n > ddof else 0.0
    low, high = bootstrap_ci(v, confidence=confidence, n_bootstrap=n_bootstrap, seed=seed)
    return Summary(mean, std, low, high, n)
