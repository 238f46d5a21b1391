"""Survival priors p(T) for persistence / emergence filters, evaluated in log space.

All functions take durations ``t`` in seconds measured from the filter's start (origin) and return
``log S(t) = log P(T > t)`` for every mixture component, so that nothing underflows even when
``rate * t`` is in the thousands.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError

__all__ = ["SurvivalMixture", "SURVIVAL_FAMILIES", "log1mexp", "log_sub_exp"]

SURVIVAL_FAMILIES = ("exponential", "lognormal", "weibull", "loglogistic")
"""Families and their two parameters ``(p1, p2)``:

- ``exponential``: p1 = rate (1/s), p2 unused;
- ``lognormal``: p1 = mu, p2 = sigma of ln T (T in seconds);
- ``weibull``: p1 = shape k, p2 = scale (s);
- ``loglogistic``: p1 = shape beta, p2 = scale alpha (s, the median).
"""


def log1mexp(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``log(1 - exp(x))`` for ``x <= 0``, accurate everywhere (Maechler 2012); -inf at x = 0."""
    x = np.minimum(np.asarray(x, dtype=np.float64), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(x > -0.6931471805599453, np.log(-np.expm1(x)), np.log1p(-np.exp(x)))
    return out


def log_sub_exp(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``log(exp(a) - exp(b))`` for ``b <= a`` (-inf when equal or when a is -inf)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    finite = np.isfinite(a)
    with np.errstate(invalid="ignore"):
        d = np.where(finite, b - a, -np.inf)
    return np.where(finite, a + log1mexp(d), -np.inf)


@dataclass(frozen=True)
class SurvivalMixture:
    """A mixture of survival-time distributions of one family.

    Attributes:
        family: one of :data:`SURVIVAL_FAMILIES`.
        weights: (K,) prior weights pi_l, summing to 1.
        p1: (K,) first parameter per component (see :data:`SURVIVAL_FAMILIES`).
        p2: (K,) second parameter per component.
    """

    family: str
    weights: NDArray[np.float64]
    p1: NDArray[np.float64]
    p2: NDArray[np.float64]

    def __post_init__(self) -> None:
        if self.family not in SURVIVAL_FAMILIES:
            raise EstimatorError(f"unknown survival family {self.family!r}; valid: {', '.join(SURVIVAL_FAMILIES)}")
        w = np.atleast_1d(np.asarray(self.weights, dtype=np.float64))
        p1 = np.atleast_1d(np.asarray(self.p1, dtype=np.float64))
        p2 = np.atleast_1d(np.asarray(self.p2, dtype=np.float64))
        if not (w.shape == p1.shape == p2.shape) or w.ndim != 1 or w.size == 0:
            raise EstimatorError(f"survival mixture: weights/p1/p2 must be equal-length 1-D arrays, got "
                                 f"{w.shape}, {p1.shape}, {p2.shape}")
        if np.any(w < 0) or not np.isfinite(w).all() or w.sum() <= 0:
            raise EstimatorError("survival mixture: weights must be non-negative and sum to a positive value")
        if self.family != "lognormal" and np.any(p1 <= 0):
            raise EstimatorError(f"survival mixture ({self.family}): p1 must be > 0")
        if self.family != "exponential" and np.any(p2 <= 0):
            raise EstimatorError(f"survival mixture ({self.family}): p2 must be > 0")
        object.__setattr__(self, "weights", w / w.sum())
        object.__setattr__(self, "p1", p1)
        object.__setattr__(self, "p2", p2)

    @property
    def n_components(self) -> int:
        return int(self.weights.size)

    @property
    def log_weights(self) -> NDArray[np.float64]:
        with np.errstate(divide="ignore"):
            return np.log(self.weights)

    def log_sf(self, t: ArrayLike) -> NDArray[np.float64]:
        """log S_l(t) for every component.

        Args:
            t: (...) durations in seconds since the origin; negative values count as 0.

        Returns:
            (..., K) array of log survival probabilities (0 at t = 0, non-increasing).
        """
        t = np.maximum(np.asarray(t, dtype=np.float64), 0.0)[..., None]
        f = self.family
        if f == "exponential":
            return -self.p1 * t
        with np.errstate(divide="ignore"):
            lt = np.log(t)
        if f == "lognormal":
            from scipy.special import log_ndtr

            return log_ndtr((self.p1 - lt) / self.p2)
        if f == "weibull":
            return -np.exp(self.p1 * (lt - np.log(self.p2)))
        # log-logistic: S = 1 / (1 + (t/alpha)^beta)
        z = self.p1 * (lt - np.log(self.p2))
        return -np.logaddexp(0.0, z)

    def log_sf_one(self, t: ArrayLike, k: ArrayLike) -> NDArray[np.float64]:
        """log S_k(t) for component index ``k`` (broadcast with ``t``)."""
        t = np.maximum(np.asarray(t, dtype=np.float64), 0.0)
        k = np.asarray(k, dtype=np.intp)
        p1 = self.p1[k]
        p2 = self.p2[k]
        f = self.family
        if f == "exponential":
            return -p1 * t
        with np.errstate(divide="ignore"):
            lt = np.log(t)
        if f == "lognormal":
            from scipy.special import log_ndtr

            return np.asarray(log_ndtr((p1 - lt) / p2), dtype=np.float64)
        if f == "weibull":
            return -np.exp(p1 * (lt - np.log(p2)))
        return -np.logaddexp(0.0, p1 * (lt - np.log(p2)))

    def to_dict(self) -> dict[str, Any]:
        return {"family": self.family, "weights": self.weights.tolist(), "p1": self.p1.tolist(),
                "p2": self.p2.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SurvivalMixture:
        return cls(d["family"], np.asarray(d["weights"]), np.asarray(d["p1"]), np.asarray(d["p2"]))

    @classmethod
    def single(cls, family: str, p1: float, p2: float = 1.0) -> SurvivalMixture:
        return cls(family, np.ones(1), np.array([p1], dtype=np.float64), np.array([p2], dtype=np.float64))

    @classmethod
    def lognormal_median(cls, median_s: float, sigma: float = 1.0) -> SurvivalMixture:
        """One log-normal component with the given median (s) and sigma of ln T."""
        return cls.single("lognormal", float(np.log(median_s)), sigma)
