"""Survival priors p(T) for persistence / emergence filters, evaluated in log space.

All functions take durations ``t`` in seconds measured from the filter's start (origin) and return
``log S(t) = log P(T > t)`` for every mixture component, so that nothing underflows even when
``rate * t`` is in the thousands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError

__all__ = ["SurvivalMixture", "SURVIVAL_FAMILIES", "log_ndtr_scalar"]

_SQRT1_2 = 0.7071067811865476
_LOG_2SQRTPI = math.log(2.0 * math.sqrt(math.pi))


def log_ndtr_scalar(x: float) -> float:
    """``log Phi(x)`` for one float with the math module (matches ``scipy.special.log_ndtr`` to ~1e-14).

    Same split as scipy: ``log1p(-erfc(x/sqrt2)/2)`` for x >= -1, ``log(erfc(-x/sqrt2)/2)`` below,
    and the asymptotic series of erfcx once erfc would underflow (x < -37).
    """
    t = x * _SQRT1_2
    if x >= -1.0:
        return math.log1p(-0.5 * math.erfc(t))
    if x > -37.0:
        return math.log(0.5 * math.erfc(-t))
    u2 = t * t
    r = 1.0 / u2
    s = 1.0 + r * (-0.5 + r * (0.75 + r * (-1.875 + r * (6.5625 - r * 29.53125))))
    return -u2 - math.log(-t) - _LOG_2SQRTPI + math.log(s)

SURVIVAL_FAMILIES = ("exponential", "lognormal", "weibull", "loglogistic")
"""Families and their two parameters ``(p1, p2)``:

- ``exponential``: p1 = rate (1/s), p2 unused;
- ``lognormal``: p1 = mu, p2 = sigma of ln T (T in seconds);
- ``weibull``: p1 = shape k, p2 = scale (s);
- ``loglogistic``: p1 = shape beta, p2 = scale alpha (s, the median).
"""


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
        """Number of mixture components."""
        return int(self.weights.size)

    @property
    def log_weights(self) -> NDArray[np.float64]:
        """Natural log of the component weights."""
        with np.errstate(divide="ignore"):
            return np.log(self.weights)

    def log_sf(self, t: ArrayLike) -> NDArray[np.float64]:
        """Log S_l(t) for every component.

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

    def log_sf_rows(self, tau: NDArray[np.float64]) -> NDArray[np.float64]:
        """Log S_l(tau) as a (K, n) array for (n,) durations ``tau >= 0`` (s); the filters' batch layout."""
        f = self.family
        if f == "exponential":
            return -self.p1[:, None] * tau
        with np.errstate(divide="ignore"):
            lt = np.log(tau)
        if f == "lognormal":
            from scipy.special import log_ndtr

            return log_ndtr((self.p1[:, None] - lt) / self.p2[:, None])
        z = self.p1[:, None] * (lt - np.log(self.p2)[:, None])
        if f == "weibull":
            return -np.exp(z)
        return -np.logaddexp(0.0, z)

    def log_sf_scalar(self, tau: float) -> list[float]:
        """Log S_l(tau) for one duration ``tau`` (s) as a list of K floats (math module, no numpy).

        Equals :meth:`log_sf_rows` up to rounding (~1e-14 relative); used by the filters' one-at-a-time
        fast path, where numpy's per-call overhead dominates for a handful of components.
        """
        p1, p2 = self._scalar_params()
        f = self.family
        if f == "exponential":
            return [-a * tau for a in p1]
        if tau <= 0.0:
            return [0.0] * len(p1)
        lt = math.log(tau)
        if f == "lognormal":
            return [log_ndtr_scalar((a - lt) / b) for a, b in zip(p1, p2)]
        out = []
        for a, lb in zip(p1, p2):  # p2 holds log(scale) here
            z = a * (lt - lb)
            if f == "weibull":
                out.append(-math.exp(z) if z < 709.0 else -math.inf)
            else:
                out.append(-(z + math.log1p(math.exp(-z))) if z > 0 else -math.log1p(math.exp(z)))
        return out

    def _scalar_params(self) -> tuple[list[float], list[float]]:
        cached = self.__dict__.get("_scalar_cache")
        if cached is None:
            p2 = self.p2.tolist() if self.family in ("exponential", "lognormal") else np.log(self.p2).tolist()
            cached = (self.p1.tolist(), p2)
            object.__setattr__(self, "_scalar_cache", cached)
        return cached

    def log_sf_one(self, t: ArrayLike, k: ArrayLike) -> NDArray[np.float64]:
        """Log S_k(t) for component index ``k`` (broadcast with ``t``)."""
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
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return {"family": self.family, "weights": self.weights.tolist(), "p1": self.p1.tolist(),
                "p2": self.p2.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SurvivalMixture:
        """The object a :meth:`to_dict` dict describes."""
        return cls(d["family"], np.asarray(d["weights"]), np.asarray(d["p1"]), np.asarray(d["p2"]))

    @classmethod
    def single(cls, family: str, p1: float, p2: float = 1.0) -> SurvivalMixture:
        """A one-component mixture of ``family`` with parameters ``p1``, ``p2``."""
        return cls(family, np.ones(1), np.array([p1], dtype=np.float64), np.array([p2], dtype=np.float64))

    @classmethod
    def lognormal_median(cls, median_s: float, sigma: float = 1.0) -> SurvivalMixture:
        """One log-normal component with the given median (s) and sigma of ln T."""
        return cls.single("lognormal", float(np.log(median_s)), sigma)
