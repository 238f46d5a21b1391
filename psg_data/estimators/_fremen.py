"""FreMEn (Krajnik et al. 2017): frequency-map enhancement of a binary state, done carefully.

Candidate periods are one week / k for k = 1..K. With ``tau`` the time in seconds since a
reference epoch (local Monday 00:00 wall-clock time, so schedules survive DST) and N observations
y_i, the model keeps the additive sufficient statistics

    n, sum(y), S_k = sum_i y_i exp(-1j w_k tau_i), Z_k = sum_i exp(-1j w_k tau_i),  w_k = 2 pi k / week

so adding data in several batches gives the one-batch result (up to float rounding, ~1e-15).
The static part is mu = mean(y); the coefficient of period k is c_k = (S_k - mu Z_k) / n (the
mean-subtracted Fourier sum); the prediction with the ``order`` strongest components (ranked by
amplitude |c_k|) is ``clip(mu + sum 2 |c_k| cos(w_k tau + arg c_k), 0, 1)``.

The two rules of the public FreMEn code (strands-project/fremen, ``CFrelement``), each by name:

- **duration rule** (``FremenModel(duration_rule=True)``): a period whose 1.5 x length exceeds the
  span of the data the model was fitted on (last minus first time) gets amplitude 0, so it is
  never selected (:meth:`FremenModel.admissible`);
- **order rule** (:data:`ORDER_RULES`): ``"reference"`` scores each order 0..M on held-out data
  by the error rate of the *unclipped* estimate thresholded at 0.5 and moves to a higher order
  only when it beats the best so far by more than a tolerance (the public ``evaluate()``, 0.001);
  ``"mae"`` scores the mean |clipped prediction - y| and takes the smallest order within the
  tolerance of the best (this library's rule before the reference one became the default);
  ``"train_mse"`` is the rule of the authors' benchmark framework (``chronorobotics/framework2``,
  ``bruteForceTrain`` with ``meanError squareError`` in ``DoorState.hs``): orders 1..M, each scored
  by the mean squared error of its clipped prediction on the training data itself, the lowest wins.

Unlike the public code, periods are exact (one week / k in float64: the public code's integer
periods ``floor(604800 / k)`` s are a defect, wrong for every k that does not divide 604800), angles
are float64 on a relative epoch (the public code uses float32 angles of Unix times), and adding data
in batches equals one batch.

Because the periods are harmonics of one week, the sums for all k at once are a few FFTs: times
are binned on a fine grid of the week (M bins) and the within-bin offset is handled exactly by a
Taylor series of order P (error < 1e-17), so N = 1e6, K = 1000 costs ~0.1 s instead of N*K
complex exponentials.
"""

from __future__ import annotations

import datetime
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError

__all__ = ["WEEK_S", "ORDER_RULES", "FremenModel", "FremenComponents", "fourier_sums", "wall_seconds",
           "reference_monday", "LocalClock", "choose_order"]

WEEK_S = 7 * 86400.0
ORDER_RULES = {"reference": "error rate of (unclipped estimate > 0.5); a higher order only if better than the best "
                            "so far by more than the tolerance (public FreMEn evaluate())",
               "mae": "mean |clipped prediction - y|; the smallest order within the tolerance of the best",
               "train_mse": "mean squared error of the clipped prediction on the training data itself; the lowest "
                            "of orders 1..max_order (the authors' benchmark framework, framework2 bruteForceTrain)"}
"""Order rules by name, with what each scores and how it chooses (:func:`choose_order`)."""
DURATION_FACTOR = 1.5
"""Duration rule: a period T is kept only if DURATION_FACTOR * T <= the span of the fitted data."""
_DIRECT_LIMIT = 100_000  # N*K below which the direct sum is used


# the offset table's grid stays two days inside pandas' datetime64[ns] range (1677-09-21 .. 2262-04-11),
# where it was built with pandas before, so that its local times fit too (UTC offsets, local mean times
# included, are under a day); times beyond take the offset at the grid's end
_PANDAS_FIRST_S = math.ceil(-9223372036.854775807 / 900.0) * 900.0 + 2 * 86400.0
_PANDAS_LAST_S = math.floor(9223372036.854775807 / 900.0) * 900.0 - 2 * 86400.0
_OFFSET_TABLES: dict[str, tuple[float, float, NDArray[np.float64], NDArray[np.float64]]] = {}
_COARSE = 96
"""Grid steps (of 900 s: one day) between the offsets looked up first; a zone's offset changes at most
once in between (tzdata's offset changes are >= 6.9 days apart), found by bisection on the grid."""


def _zone(timezone: str) -> Any:
    from zoneinfo import ZoneInfo

    try:
        return ZoneInfo(timezone)
    except Exception as exc:  # unknown or malformed zone names raise several zoneinfo errors
        raise EstimatorError(f"unknown timezone {timezone!r}: {exc}") from exc


def _zone_offset(tz: Any, t: float) -> float:
    """UTC offset (s) of zone ``tz`` at Unix time ``t``."""
    return float(datetime.datetime.fromtimestamp(t, tz).utcoffset().total_seconds())  # type: ignore[union-attr]


def _offset_steps(grid: NDArray[np.float64], timezone: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(grid times where the UTC offset differs from the previous grid time, their offsets), and the
    offset at ``grid[0]`` first; from zoneinfo, one look-up per day and a bisection per change (no
    pandas: importing it was a second per worker process for these few numbers).
    """
    tz = _zone(timezone)
    last = grid.size - 1
    idx = list(range(0, last, _COARSE)) + [last]
    coarse = [_zone_offset(tz, float(grid[i])) for i in idx]
    at, offs = [float(grid[0])], [coarse[0]]
    for k in range(len(idx) - 1):
        if coarse[k + 1] == coarse[k]:
            continue
        lo, hi = idx[k], idx[k + 1]  # offset(grid[lo]) = coarse[k] != offset(grid[hi])
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if _zone_offset(tz, float(grid[mid])) == coarse[k] else (lo, mid)
        at.append(float(grid[hi]))
        offs.append(coarse[k + 1])
    return np.array(at), np.array(offs)


def _offset_table(timezone: str, lo: float, hi: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """UTC-offset steps (transition times, offsets) of ``timezone`` covering [lo, hi] (cached)."""
    tab = _OFFSET_TABLES.get(timezone)
    if tab is not None and tab[0] <= lo and hi <= tab[1]:
        return tab[2], tab[3]
    a = max(math.floor(min(lo, tab[0] if tab else lo) / 900.0) * 900.0 - 400 * 86400.0, _PANDAS_FIRST_S)
    b = min(math.ceil(max(hi, tab[1] if tab else hi) / 900.0) * 900.0 + 400 * 86400.0, _PANDAS_LAST_S)
    grid = np.arange(a, b + 900.0, 900.0)  # zone transitions happen on quarter hours
    at, offs = _offset_steps(grid, timezone)
    trans = np.concatenate([[-np.inf], at[1:]])
    _OFFSET_TABLES[timezone] = (a, b, trans, offs)
    return trans, offs


def wall_seconds(t_s: ArrayLike, timezone: str) -> NDArray[np.float64]:
    """Local wall-clock seconds (t + UTC offset at t) for Unix times ``t_s`` in ``timezone``."""
    t = np.asarray(t_s, dtype=np.float64)
    if timezone in ("UTC", "Etc/UTC", "utc", "GMT") or t.size == 0:
        return t.copy()
    lo, hi = (min(max(float(x), _PANDAS_FIRST_S), _PANDAS_LAST_S) for x in (np.min(t), np.max(t)))
    trans, offs = _offset_table(timezone, lo, hi)  # times beyond pandas' range take its end's offset
    return t + offs[np.searchsorted(trans, t, side="right") - 1]


def reference_monday(t_s: float, timezone: str) -> float:
    """Wall-clock seconds of the local Monday 00:00 at or before Unix time ``t_s``."""
    w = float(wall_seconds(np.array([t_s]), timezone)[0])
    day = math.floor(w / 86400.0)
    monday = day - ((day + 3) % 7)  # 1970-01-01 was a Thursday
    return monday * 86400.0


@dataclass(frozen=True)
class LocalClock:
    """Maps Unix seconds to seconds since a reference local Monday 00:00 (wall clock)."""

    timezone: str
    ref_wall_s: float

    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]:
        return wall_seconds(t_s, self.timezone) - self.ref_wall_s

    @classmethod
    def before(cls, t_s: float, timezone: str) -> LocalClock:
        """A clock whose origin is the local Monday 00:00 (``timezone``) at or before Unix time ``t_s``."""
        return cls(timezone, reference_monday(t_s, timezone))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return {"timezone": self.timezone, "ref_wall_s": self.ref_wall_s}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LocalClock:
        """The object a :meth:`to_dict` dict describes."""
        return cls(d["timezone"], float(d["ref_wall_s"]))


def _direct_sums(tau: NDArray[np.float64], w: NDArray[np.float64], k: int, base: float) -> NDArray[np.complex128]:
    out = np.zeros(k, dtype=np.complex128)
    theta = np.mod(tau, base) * (2 * np.pi / base)
    ks = np.arange(1, k + 1, dtype=np.float64)
    step = max(1, _DIRECT_LIMIT // max(k, 1) // 4)
    for s in range(0, tau.size, step):
        ang = np.outer(theta[s:s + step], ks)
        out += (w[s:s + step, None] * np.exp(-1j * ang)).sum(axis=0)
    return out


def _fft_sums(tau: NDArray[np.float64], w: NDArray[np.float64], k: int, base: float) -> NDArray[np.complex128]:
    m = 1 << max(16, int(math.ceil(math.log2(64 * k))))
    h = base / m
    theta = np.mod(tau, base)
    b = np.minimum((theta / h).astype(np.int64), m - 1)
    u = theta / h - b  # in [0, 1)
    ks = np.arange(1, k + 1)
    z = -1j * 2 * np.pi * ks / m  # (-i w_k h)
    out = np.zeros(k, dtype=np.complex128)
    up = w.copy()
    zp = np.ones(k, dtype=np.complex128)
    fact = 1.0
    for p in range(12):  # |w_K h| <= 2 pi / 64 ~ 0.098: 0.098^12 / 12! ~ 2e-21
        if p > 0:
            up = up * u
            zp = zp * z
            fact *= p
        mom = np.bincount(b, weights=up, minlength=m)
        out += zp / fact * np.fft.fft(mom)[1:k + 1]
    return out


def fourier_sums(tau: ArrayLike, weights: ArrayLike, n_periods: int, base_period_s: float = WEEK_S,
                 method: str = "auto") -> NDArray[np.complex128]:
    """sum_i weights_i exp(-1j 2 pi k tau_i / base) for k = 1..n_periods.

    Args:
        tau: (N,) times in seconds since the reference epoch (float64).
        weights: (N,) weights (observations, or ones).
        n_periods: K.
        base_period_s: the longest period (one week).
        method: "direct", "fft" or "auto" (fft when N*K is large).
    """
    tau = np.asarray(tau, dtype=np.float64).reshape(-1)
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if tau.size == 0 or n_periods == 0:
        return np.zeros(n_periods, dtype=np.complex128)
    if method == "direct" or (method == "auto" and tau.size * n_periods <= _DIRECT_LIMIT):
        return _direct_sums(tau, w, n_periods, base_period_s)
    return _fft_sums(tau, w, n_periods, base_period_s)


@dataclass(frozen=True)
class FremenComponents:
    """A fitted FreMEn predictor: static part and selected periodic components.

    Attributes:
        mean: static part mu.
        k: (m,) harmonic indices (period = base / k).
        coef: (m,) complex coefficients c_k (prediction adds 2 |c_k| cos(w_k tau + arg c_k)).
        base_period_s: the base period (one week).
    """

    mean: float
    k: NDArray[np.int64]
    coef: NDArray[np.complex128]
    base_period_s: float = WEEK_S

    @property
    def order(self) -> int:
        """Number of periodic components."""
        return int(self.k.size)

    def raw(self, tau: ArrayLike) -> NDArray[np.float64]:
        """Unclipped reconstruction at times ``tau`` (s since the reference epoch)."""
        tau = np.asarray(tau, dtype=np.float64)
        out = np.full(tau.shape, self.mean, dtype=np.float64)
        if self.k.size:
            theta = np.mod(tau, self.base_period_s) * (2 * np.pi / self.base_period_s)
            k, amp, ph = self._terms
            # every component's term at once (the same operations per element), then summed in order
            terms = amp * np.cos(k * theta[..., None] + ph)
            for j in range(k.size):
                out += terms[..., j]
        return out

    @functools.cached_property
    def _terms(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """(m,) harmonic indices as floats, amplitudes 2 |c_k| and phases arg c_k."""
        return self.k.astype(np.float64), 2 * np.abs(self.coef), np.angle(self.coef)

    def predict(self, tau: ArrayLike) -> NDArray[np.float64]:
        """Prediction saturated to [0, 1] (the paper's sigma)."""
        return np.clip(self.raw(tau), 0.0, 1.0)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return {"mean": self.mean, "k": self.k.tolist(), "re": self.coef.real.tolist(), "im": self.coef.imag.tolist(),
                "base_period_s": self.base_period_s}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FremenComponents:
        """The object a :meth:`to_dict` dict describes."""
        coef = np.asarray(d["re"], dtype=np.float64) + 1j * np.asarray(d["im"], dtype=np.float64)
        return cls(float(d["mean"]), np.asarray(d["k"], dtype=np.int64), coef, float(d["base_period_s"]))


class FremenModel:
    """Additive FreMEn statistics over K harmonics of ``base_period_s``.

    Args:
        n_periods: K, number of candidate periods (base / k, k = 1..K).
        base_period_s: one week by default.
        duration_rule: zero the amplitude of every period T with 1.5 T > :attr:`span_s` (the
            public FreMEn code's rule); False keeps every period.
    """

    def __init__(self, n_periods: int = 1000, base_period_s: float = WEEK_S, duration_rule: bool = False) -> None:
        if n_periods < 0:
            raise EstimatorError(f"n_periods must be >= 0, got {n_periods}")
        self.n_periods = int(n_periods)
        self.base_period_s = float(base_period_s)
        self.duration_rule = bool(duration_rule)
        self.n = 0
        self.sum_y = 0.0
        self.first_tau = math.inf
        self.last_tau = -math.inf
        self.s = np.zeros(self.n_periods, dtype=np.complex128)
        self.z = np.zeros(self.n_periods, dtype=np.complex128)

    def add(self, tau: ArrayLike, y: ArrayLike, method: str = "auto") -> FremenModel:
        """Add observations (tau in s since the reference epoch, y in [0, 1])."""
        tau = np.asarray(tau, dtype=np.float64).reshape(-1)
        y = np.asarray(y, dtype=np.float64).reshape(-1)
        if tau.shape != y.shape:
            raise EstimatorError(f"FreMEn: tau and y differ in length ({tau.size} vs {y.size})")
        if tau.size == 0:
            return self
        self.n += int(tau.size)
        self.sum_y += float(y.sum())
        self.first_tau = min(self.first_tau, float(tau.min()))
        self.last_tau = max(self.last_tau, float(tau.max()))
        self.s += fourier_sums(tau, y, self.n_periods, self.base_period_s, method)
        self.z += fourier_sums(tau, np.ones_like(tau), self.n_periods, self.base_period_s, method)
        return self

    @property
    def mean(self) -> float:
        """The static term: the mean of the observations (0.5 before any)."""
        return self.sum_y / self.n if self.n else 0.5

    @property
    def span_s(self) -> float:
        """Last minus first observation time, seconds (0 before any)."""
        return self.last_tau - self.first_tau if self.n else 0.0

    def admissible(self) -> NDArray[np.bool_]:
        """(K,) which periods may carry an amplitude: all, or under the duration rule 1.5 T <= span."""
        if not self.duration_rule:
            return np.ones(self.n_periods, dtype=bool)
        periods = self.base_period_s / np.arange(1, self.n_periods + 1, dtype=np.float64)
        return DURATION_FACTOR * periods <= self.span_s

    def coefficients(self) -> NDArray[np.complex128]:
        """(K,) c_k = (S_k - mu Z_k) / n (0 for a period the duration rule drops)."""
        if self.n == 0:
            return np.zeros(self.n_periods, dtype=np.complex128)
        return np.where(self.admissible(), (self.s - self.mean * self.z) / self.n, 0.0)

    def ranking(self) -> NDArray[np.int64]:
        """Harmonic indices (1-based) sorted by decreasing amplitude (stable)."""
        amp = np.abs(self.coefficients())
        return (np.argsort(-amp, kind="stable") + 1).astype(np.int64)

    def components(self, order: int) -> FremenComponents:
        """The predictor with the ``order`` strongest components."""
        c = self.coefficients()
        ks = self.ranking()[: max(0, int(order))]
        return FremenComponents(self.mean, ks, c[ks - 1], self.base_period_s)

    def order_scores(self, tau: ArrayLike, y: ArrayLike, max_order: int | None = None,
                     rule: str = "reference") -> NDArray[np.float64]:
        """(M+1,) held-out score of orders 0..M (M = ``max_order``, at most K; None: K), lower is better.

        ``rule`` (:data:`ORDER_RULES`): "reference" gives the error rate of (unclipped estimate > 0.5)
        against y, "mae" the mean |clipped prediction - y|, "train_mse" the mean squared error of the
        clipped prediction.
        """
        if rule not in ORDER_RULES:
            raise EstimatorError(f"FreMEn: order rule must be one of {', '.join(ORDER_RULES)}, got {rule!r}")
        tau = np.asarray(tau, dtype=np.float64).reshape(-1)
        y = np.asarray(y, dtype=np.float64).reshape(-1)
        mo = self.n_periods if max_order is None else min(int(max_order), self.n_periods)
        c = self.coefficients()
        ks = self.ranking()[:mo]
        err = np.zeros(mo + 1)
        if tau.size == 0:
            return err
        theta = np.mod(tau, self.base_period_s) * (2 * np.pi / self.base_period_s)
        amp = 2 * np.abs(c[ks - 1])
        ph = np.angle(c[ks - 1])
        step = max(1, 4_000_000 // max(mo, 1))
        for s in range(0, tau.size, step):
            th = theta[s:s + step]
            contrib = amp * np.cos(np.outer(th, ks) + ph)
            pred = np.empty((th.size, mo + 1))
            pred[:, 0] = self.mean
            np.cumsum(contrib, axis=1, out=pred[:, 1:])
            pred[:, 1:] += self.mean
            est = (pred > 0.5).astype(np.float64) if rule == "reference" else np.clip(pred, 0.0, 1.0)
            diff = np.abs(est - y[s:s + step, None])
            err += (diff * diff if rule == "train_mse" else diff).sum(axis=0)
        return err / tau.size

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"n_periods": self.n_periods, "base_period_s": self.base_period_s, "duration_rule": self.duration_rule,
                "n": self.n, "sum_y": self.sum_y, "first_tau": self.first_tau, "last_tau": self.last_tau,
                "s_re": self.s.real.tolist(), "s_im": self.s.imag.tolist(), "z_re": self.z.real.tolist(),
                "z_im": self.z.imag.tolist()}


def choose_order(scores: ArrayLike, tol: float, rule: str = "reference") -> int:
    """The order (index into ``scores``, orders 0..M) that ``rule`` (:data:`ORDER_RULES`) chooses.

    "reference": start at order 0 and move to order j only if ``scores[j] < best - tol``, best being
    the score of the order chosen so far (the public ``evaluate()``); "mae": the smallest order
    whose score is within ``tol`` of the minimum; "train_mse": the lowest score among orders 1..M
    (the first on a tie; order 0 only when M is 0), ``tol`` unused.
    """
    s = np.asarray(scores, dtype=np.float64).reshape(-1)
    if rule == "train_mse":
        return 1 + int(np.argmin(s[1:])) if s.size > 1 else 0
    if rule == "mae":
        return int(np.flatnonzero(s <= float(np.min(s)) + tol)[0])
    if rule != "reference":
        raise EstimatorError(f"FreMEn: order rule must be one of {', '.join(ORDER_RULES)}, got {rule!r}")
    best, order = math.inf, 0
    for j, v in enumerate(s):
        if v < best - tol:
            best, order = float(v), j
    return order
