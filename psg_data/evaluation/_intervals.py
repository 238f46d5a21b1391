"""Confidence intervals with a stated meaning: what was resampled, how, how many.

Two situations, two intervals (scipy.stats ``t.interval`` / ``bootstrap`` conventions):

- **Over independent repetitions** (regenerated labs ``--lab-seeds``, benchmark draws, estimator
  seeds): the Student t-interval of the mean, ``mean ± t_{n-1, 1-a/2} s / sqrt(n)``
  (:func:`t_interval`). Exact for normal values, and it covers at >= 90 % of the nominal 95 % for
  the 3-10 repetitions a benchmark has (tests/evaluation/test_intervals.py simulates it).
- **Within one dataset**: the score is a ratio ``sum_o N_o / sum_o D_o`` over objects ``o``
  (``N`` = span-weighted metric sums of the object's edges, ``D`` = their spans; edges of one
  object are not independent, so objects are the resampled unit). With >= 10 objects:
  the *expanded percentile bootstrap* over objects (Hesterberg 2015: percentiles at
  ``Phi(sqrt(n / (n - 1)) t_{n-1, a/2})`` instead of ``a/2``, which corrects the percentile
  interval's narrowness at small n), :func:`cluster_bootstrap`; with fewer objects, a t-interval
  with the delete-one-object jackknife standard error (:func:`cluster_jackknife`), since a bootstrap
  of 3-9 units cannot reach its nominal coverage. Navigation resamples queries the same way.

Every interval is an :class:`Interval` carrying its method, the resampled unit and n; a
single value (n = 1) has no interval (``low = high = NaN``) and says so.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EvaluationError

__all__ = ["Interval", "t_interval", "cluster_bootstrap", "cluster_jackknife", "ratio_interval",
           "MIN_BOOTSTRAP_UNITS", "describe_interval"]

MIN_BOOTSTRAP_UNITS = 10
"""Fewer resampled units than this: the jackknife t-interval instead of the bootstrap."""


def _t_ppf(q: float, df: int) -> float:
    """Student t quantile: ``scipy.stats.t.ppf(q, df)`` (which calls this ufunc), without importing
    scipy.stats (1-3 s, the largest import of a run's serial part) for one number.
    """
    from scipy.special import stdtrit

    return float(stdtrit(df, q))


@functools.lru_cache(maxsize=64)
def _bootstrap_level(n: int, confidence: float) -> float:
    """Hesterberg's lower percentile level ``Phi(sqrt(n / (n - 1)) t_{n-1, a/2})`` (= ``scipy.stats.norm.cdf``)."""
    from scipy.special import ndtr

    return float(ndtr(math.sqrt(n / (n - 1)) * _t_ppf((1.0 - confidence) / 2.0, n - 1)))


@dataclass(frozen=True)
class Interval:
    """A point estimate with its confidence interval.

    Attributes:
        estimate: the point estimate.
        low, high: interval ends (NaN when there is no interval).
        n: number of resampled units (repetitions, objects, queries).
        method: ``t`` (t-interval over repetitions), ``bootstrap`` (expanded percentile bootstrap),
            ``jackknife-t`` or ``none``.
        unit: what was resampled (``lab draws``, ``seeds``, ``objects``, ``queries``).
        confidence: nominal coverage.
    """

    estimate: float
    low: float
    high: float
    n: int
    method: str
    unit: str
    confidence: float = 0.95

    @property
    def half_width(self) -> float:
        """Half the interval's width (the ± printed in tables)."""
        return (self.high - self.low) / 2.0 if math.isfinite(self.low) and math.isfinite(self.high) else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Interval:
        """The object a :meth:`to_dict` dict describes."""
        nan = float("nan")
        return Interval(nan if d.get("estimate") is None else float(d["estimate"]),
                        nan if d.get("low") is None else float(d["low"]),
                        nan if d.get("high") is None else float(d["high"]), int(d.get("n") or 0),
                        str(d.get("method", "none")), str(d.get("unit", "")), float(d.get("confidence", 0.95)))


def _check_confidence(confidence: float) -> None:
    if not 0.0 < confidence < 1.0:
        raise EvaluationError(f"confidence must be in (0, 1), got {confidence}")


def t_interval(values: ArrayLike, *, confidence: float = 0.95, unit: str = "repetitions") -> Interval:
    """Student t-interval of the mean of independent repetitions (NaN values dropped).

    Example:
        >>> iv = t_interval([0.5, 0.7])
        >>> round(iv.estimate, 3), round(iv.low, 3), round(iv.high, 3)
        (0.6, -0.671, 1.871)
    """
    _check_confidence(confidence)
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    n = int(v.size)
    if n == 0:
        return Interval(float("nan"), float("nan"), float("nan"), 0, "none", unit, confidence)
    mean = float(np.mean(v))
    if n == 1:
        return Interval(mean, float("nan"), float("nan"), 1, "none", unit, confidence)
    half = float(_t_ppf(0.5 + confidence / 2.0, n - 1) * np.std(v, ddof=1) / math.sqrt(n))
    return Interval(mean, mean - half, mean + half, n, "t", unit, confidence)


def _ratio_start(num: ArrayLike, den: ArrayLike, unit: str, confidence: float
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], Interval | None]:
    """Units kept, and the interval when there are fewer than two (no spread to estimate)."""
    _check_confidence(confidence)
    n_, d_ = _ratio_inputs(num, den)
    nan = float("nan")
    if n_.size == 0:
        return n_, d_, Interval(nan, nan, nan, 0, "none", unit, confidence)
    if n_.size == 1:
        return n_, d_, Interval(float(n_.sum() / d_.sum()), nan, nan, 1, "none", unit, confidence)
    return n_, d_, None


def _ratio_inputs(num: ArrayLike, den: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    n = np.asarray(num, dtype=np.float64).reshape(-1)
    d = np.asarray(den, dtype=np.float64).reshape(-1)
    if n.shape != d.shape:
        raise EvaluationError(f"ratio interval: {n.size} numerators for {d.size} denominators")
    keep = np.isfinite(n) & np.isfinite(d) & (d > 0)
    return n[keep], d[keep]


@functools.lru_cache(maxsize=16)
def _resample_counts(n: int, n_bootstrap: int, seed: int) -> NDArray[np.float64]:
    """(n_bootstrap, n) times each unit is drawn per resample (``default_rng(seed).multinomial``; read-only).

    The same for every interval of a run with the same number of units: a run's breakdowns ask for
    hundreds of intervals over the same 21 objects, and drawing the counts was 70 % of each.
    """
    counts = np.random.default_rng(seed).multinomial(n, np.full(n, 1.0 / n), size=n_bootstrap).astype(np.float64)
    counts.flags.writeable = False
    return counts


def cluster_bootstrap(num: ArrayLike, den: ArrayLike, *, confidence: float = 0.95, n_bootstrap: int = 2000,
                      seed: int = 0, unit: str = "objects") -> Interval:
    """Expanded percentile bootstrap of the ratio ``sum(num) / sum(den)`` over units (module docstring).

    Args:
        num: (n,) per-unit numerators (e.g. span-weighted metric sums of an object's edges).
        den: (n,) per-unit denominators (their spans); units with ``den <= 0`` are dropped.
        confidence: nominal coverage.
        n_bootstrap: resamples (``numpy.random.default_rng(seed)``, deterministic).
        seed: bootstrap seed.
        unit: name of the resampled unit.
    """
    if n_bootstrap < 1:
        raise EvaluationError(f"n_bootstrap must be >= 1, got {n_bootstrap}")
    n_, d_, trivial = _ratio_start(num, den, unit, confidence)
    if trivial is not None:
        return trivial
    n, est = int(n_.size), float(n_.sum() / d_.sum())
    counts = _resample_counts(n, n_bootstrap, seed)
    den_b = counts @ d_
    stat = (counts @ n_) / np.where(den_b > 0, den_b, np.nan)
    a = _bootstrap_level(n, float(confidence))
    low, high = np.nanquantile(stat, [a, 1.0 - a])
    return Interval(est, float(low), float(high), n, "bootstrap", unit, confidence)


def cluster_jackknife(num: ArrayLike, den: ArrayLike, *, confidence: float = 0.95, unit: str = "objects") -> Interval:
    """t-interval of the ratio ``sum(num) / sum(den)`` with the delete-one-unit jackknife standard error.

    With equal denominators this is exactly the t-interval of the per-unit ratios.
    """
    n_, d_, trivial = _ratio_start(num, den, unit, confidence)
    if trivial is not None:
        return trivial
    n, est = int(n_.size), float(n_.sum() / d_.sum())
    loo = (n_.sum() - n_) / (d_.sum() - d_)
    se = math.sqrt((n - 1) / n * float(np.sum((loo - loo.mean()) ** 2)))
    half = _t_ppf(0.5 + confidence / 2.0, n - 1) * se
    return Interval(est, est - half, est + half, n, "jackknife-t", unit, confidence)


def ratio_interval(num: ArrayLike, den: ArrayLike, *, confidence: float = 0.95, n_bootstrap: int = 2000,
                   seed: int = 0, unit: str = "objects") -> Interval:
    """The within-dataset default: :func:`cluster_bootstrap` with >= :data:`MIN_BOOTSTRAP_UNITS` units,
    else :func:`cluster_jackknife`.
    """
    n_, _ = _ratio_inputs(num, den)
    if n_.size >= MIN_BOOTSTRAP_UNITS:
        return cluster_bootstrap(num, den, confidence=confidence, n_bootstrap=n_bootstrap, seed=seed, unit=unit)
    return cluster_jackknife(num, den, confidence=confidence, unit=unit)


def describe_interval(method: str, unit: str, n: int, confidence: float = 0.95, *, extra: str = "") -> str:
    """The one line under a table that says what ``±`` is."""
    pct = f"{100 * confidence:g} %"
    if method == "t":
        what = f"t-interval over {n} {unit} (mean ± t * s / sqrt(n))"
    elif method == "bootstrap":
        what = f"expanded percentile bootstrap over the {n} {unit} ({unit} resampled whole)"
    elif method == "jackknife-t":
        what = f"t-interval over the {n} {unit} with a jackknife standard error (too few {unit} for a bootstrap)"
    else:
        return f"±: no interval (a single {_singular(unit) or 'value'}, nothing varies){extra}"
    return f"±: half-width of the {pct} {what}{extra}"


def _singular(unit: str) -> str:
    """The singular of a plural unit name in English ("queries" -> "query", "objects" -> "object")."""
    if unit.endswith("ies"):
        return unit[:-3] + "y"
    return unit[:-1] if unit.endswith("s") else unit
