"""Mixtures of survival distributions fitted to interval-censored durations by EM.

Sparse observation does not reveal when a run ended, only that it ended somewhere between its last
observation and the next opposite one: duration ``T`` lies in ``(lo, hi]`` (``hi = inf``: still
running at the end of the data, right-censored; ``lo == hi``: observed exactly). With weights
``w_i`` (counts, or shrinkage weights of pooled data) the log likelihood of a K-component mixture is

    log L = sum_i w_i log sum_k pi_k P_k(lo_i < T <= hi_i)      (density for exact rows)

and EM treats the component label *and* the exact duration inside each interval as missing. The
E-step needs the closed-form interval integrals of each family:

- ``lognormal`` (x = ln T ~ N(mu, sigma^2); a = (ln lo - mu)/sigma, b = (ln hi - mu)/sigma):
  P = Phi(b) - Phi(a), E[z] = (phi(a) - phi(b)) / P, E[z^2] = 1 + (a phi(a) - b phi(b)) / P
  (truncated-normal moments); M-step mu = sum r E[x] / sum r, then sigma from E[(x - mu)^2];
- ``exponential`` (rate lam; d = hi - lo): P = exp(-lam lo) - exp(-lam hi),
  E[T] = lo + 1/lam - d / expm1(lam d); M-step lam = sum r / sum r E[T];
- ``weibull`` (shape k, scale s): P = exp(-(lo/s)^k) - exp(-(hi/s)^k); the shape has no
  closed-form update even for exact data, so each M-step maximises the component's expected
  log likelihood sum_i r_ik log P_k(interval_i) over (k, s) numerically from the current values
  (a generalised EM step: it never lowers the likelihood).

Every step is computed in log space (``log_ndtr``, ``expm1``) so that intervals deep in a tail do
not underflow; tiny intervals
(``lam d < 1e-8``, a width < 1e-5 in z = (ln T - mu) / sigma, ``(hi/s)^k - (lo/s)^k < 1e-8``),
including widths near the underflow limit, use series expansions instead of differences that
cancel or underflow. Sigma (of ln T) is floored at ``sigma_min`` so that a component cannot
collapse on one duration. The likelihood never decreases from one iteration to the next (tested).
K = 1..max_components is chosen by AIC (3K parameters for log-normal and Weibull, 2K for
exponential, as the Perpetua reference), trying K upward and stopping at the first K whose AIC
does not improve on K - 1; components with weight < 0.01 are dropped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._survival import SurvivalMixture

__all__ = ["IntervalFit", "fit_interval_mixture", "fit_interval_mixtures", "interval_log_likelihood", "em_intervals",
           "INTERVAL_FAMILIES"]

INTERVAL_FAMILIES = ("lognormal", "exponential", "weibull")
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_N_PARAMS = {"lognormal": 3, "exponential": 2, "weibull": 3}


@dataclass
class IntervalFit:
    """Result of :func:`fit_interval_mixture`.

    Attributes:
        mixture: the selected mixture (components with weight < 0.01 dropped).
        log_likelihood: its log likelihood (weighted; densities of exact rows in T).
        aic: 2 * n_params - 2 * log_likelihood.
        aic_by_k: AIC of the best fit for every K tried.
        n_rows: distinct (lo, hi) rows after merging duplicates; n_weight: total weight.
        trace: log likelihood after each iteration of the selected run.
    """

    mixture: SurvivalMixture
    log_likelihood: float
    aic: float
    aic_by_k: dict[int, float]
    n_rows: int
    n_weight: float
    trace: list[float] = field(default_factory=list)


def _log_diff_ndtr(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """log(Phi(b) - Phi(a)) for a <= b, accurate in both tails."""
    from scipy.special import log_ndtr

    upper = a > 0  # both in the upper tail: use Phi(-a) - Phi(-b)
    hi = log_ndtr(np.where(upper, -a, b))
    lo = log_ndtr(np.where(upper, -b, a))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = hi + np.log1p(-np.exp(lo - hi))
    return np.where(hi == -np.inf, -np.inf, out)


def _prepare(lo_in: ArrayLike, hi_in: ArrayLike, weights: ArrayLike | None) -> tuple[NDArray[np.float64], ...]:
    lo = np.asarray(lo_in, dtype=np.float64).reshape(-1)
    hi = np.asarray(hi_in, dtype=np.float64).reshape(-1)
    w = np.ones(lo.size) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if not (lo.shape == hi.shape == w.shape):
        raise EstimatorError(f"interval EM: lo, hi and weights differ in length ({lo.size}, {hi.size}, {w.size})")
    ok = np.isfinite(lo) & (lo >= 0) & ~np.isnan(hi) & (hi >= lo) & (w > 0) & np.isfinite(w)
    ok &= (hi > 0)
    lo, hi, w = lo[ok], hi[ok], w[ok]
    if lo.size == 0:
        raise EstimatorError("interval EM: no usable intervals (need 0 <= lo <= hi, hi > 0, weight > 0)")
    # merge duplicate rows (sparse scans give many equal intervals)
    key = np.stack([lo, hi])
    uniq, inv = np.unique(key, axis=1, return_inverse=True)
    wsum = np.bincount(inv.reshape(-1), weights=w).astype(np.float64)
    return uniq[0].copy(), uniq[1].copy(), wsum


# ---------------------------------------------------------------------------------- per family
def _estep_lognormal(lo: NDArray[np.float64], hi: NDArray[np.float64], mu: NDArray[np.float64],
                     sd: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(..., n, K) log P (or log density of ln T for exact rows), E[x], E[(x - mu)^2]; rows (n,) or (R, n)."""
    with np.errstate(divide="ignore"):
        la, lb = np.log(lo)[..., None], np.log(hi)[..., None]
    exact = (lo == hi)[..., None]
    any_exact = bool(exact.any())  # without exact rows every np.where(exact, ., x) below is x: skipped
    a = (la - mu) / sd
    b = (lb - mu) / sd
    with np.errstate(invalid="ignore"):
        if any_exact:
            logp = np.where(exact, -np.log(sd) - _LOG_SQRT_2PI - 0.5 * a * a,
                            _log_diff_ndtr(a, np.where(exact, a + 1, b)))
        else:
            logp = _log_diff_ndtr(a, b)
        fa, fb = np.isfinite(a), np.isfinite(b)
        lpa = np.where(fa, -_LOG_SQRT_2PI - 0.5 * a * a, -np.inf)
        lpb = np.where(fb, -_LOG_SQRT_2PI - 0.5 * b * b, -np.inf)
        ra = np.exp(np.minimum(lpa - logp, 700.0))
        rb = np.exp(np.minimum(lpb - logp, 700.0))
        ez = ra - rb
        ez2 = 1.0 + np.where(fa, a * ra, 0.0) - np.where(fb, b * rb, 0.0)
    # narrow intervals (width h < 1e-5 in z, e.g. 1 ms at 1 h): Phi(b) - Phi(a) and the moment
    # ratios cancel to ~eps / h; expand around the midpoint m instead (error O(h^4))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        h = np.log1p((hi - lo) / lo)[..., None] / sd
    narrow = ~exact & (h < 1e-5)
    if narrow.any():
        with np.errstate(invalid="ignore"):
            m = np.where(narrow, 0.5 * (a + b), 0.0)
        h = np.where(narrow, h, 1.0)
        logp = np.where(narrow, np.log(h) - _LOG_SQRT_2PI - 0.5 * m * m + np.log1p(h * h * (m * m - 1.0) / 24.0),
                        logp)
        ez = np.where(narrow, m - m * h * h / 12.0, ez)
        ez2 = np.where(narrow, m * m + h * h * (1.0 - 2.0 * m * m) / 12.0, ez2)
    if any_exact:
        ez = np.where(exact, a, ez)
        ez2 = np.where(exact, a * a, np.maximum(ez2, ez * ez))
    else:
        ez2 = np.maximum(ez2, ez * ez)
    bad = ~np.isfinite(logp)
    ez = np.where(bad, 0.0, ez)
    ez2 = np.where(bad, 1.0, ez2)
    return logp, mu + sd * ez, sd * sd * ez2


def _estep_exponential(lo: NDArray[np.float64], hi: NDArray[np.float64],
                       lam: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(..., n, K) log P (log density for exact rows) and E[T]; rows (n,) or (R, n)."""
    exact = (lo == hi)[..., None]
    a = lo[..., None]
    d = (hi - lo)[..., None]
    ld = lam * d  # may be subnormal or 0 for widths near the underflow limit: only used where >= 1e-8
    small = ld < 1e-8
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # log(1 - e^-x) = log x - x/2 + O(x^2) for x = lam d < 1e-8, without forming lam d
        tail = np.where(np.isinf(d), 0.0, np.where(small, np.log(lam) + np.log(d) - 0.5 * ld,
                                                   np.log(-np.expm1(-ld))))
        logp = np.where(exact, np.log(lam) - lam * a, -lam * a + tail)
        corr = np.where(np.isinf(d) | (ld > 700), 0.0, d / np.expm1(ld))
        # E[T] - lo = d (1/x - 1/expm1(x)) = d (1/2 - x/12 + O(x^3)) for small x: the series avoids
        # 1/lam - d/x (cancellation) and 1/x (overflow for subnormal x)
        et = np.where(exact, a, np.where(small, a + d * (0.5 - ld / 12.0), a + 1.0 / lam - corr))
    return logp, et


def _weibull_log_mass(ka: NDArray[np.float64], kb: NDArray[np.float64], kw: NDArray[np.float64],
                      lo_pos: NDArray[np.bool_]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """log(exp(-ua) - exp(-ub)) with ua = e^ka = (lo/s)^k, ub = e^kb, kw = k log(hi/lo) (from log1p).

    D = ub - ua is taken as ua expm1(kw) where kw < 1 (ub - ua cancels to ~eps ua / D for narrow
    intervals) and, where D < 1e-8 (narrow intervals, or (hi/s)^k near the underflow limit), in
    logs: log D = kb + log(1 - e^-kw) (kw = inf for lo = 0), log(1 - e^-D) = log D - D/2 + O(D^2).
    Also returns where that branch was taken.
    """
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        ua, ub = np.exp(ka), np.exp(kb)
        d = np.where(np.isinf(kb), np.inf, np.where(lo_pos & (kw < 1.0), ua * np.expm1(kw), ub - ua))
        wide = -ua + np.log(-np.expm1(-d))
        small = d < 1e-8
        if not small.any():
            return wide, small
        logd = kb + np.log(-np.expm1(-np.where(lo_pos, kw, np.inf)))
        return np.where(small, -ua + logd - 0.5 * np.exp(logd), wide), small


def _weibull_logp(lo: NDArray[np.float64], hi: NDArray[np.float64], k: NDArray[np.float64],
                  s: NDArray[np.float64]) -> NDArray[np.float64]:
    exact = (lo == hi)[:, None]
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        za = np.log(lo)[:, None] - np.log(s)
        zb = np.log(hi)[:, None] - np.log(s)
        ua = np.exp(k * za)
        kw = k * np.log1p((hi - lo) / lo)[:, None]
        mass = _weibull_log_mass(k * za, k * zb, kw, (lo > 0)[:, None])[0]
        dens = np.log(k) - np.log(s) + (k - 1.0) * za - ua
        # S(lo) = 0 to double precision (ua = inf): P(lo < T <= hi) is 0, not inf - inf
        interval = np.where(np.isinf(ua), -np.inf, mass)
    return np.where(exact, dens, interval)


def _weibull_nll_grad(v: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64],
                      wr: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
    """-sum wr log P and its gradient in (ln k, ln s) for one Weibull component."""
    k, ls = math.exp(v[0]), v[1]
    exact = lo == hi
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        za = np.log(lo) - ls
        zb = np.log(hi) - ls
        # (t/s)^k capped at e^50 (the survival is 0 to double precision there) so that the line
        # search never meets inf; the capped part has zero derivative
        ka, kb = np.minimum(k * za, 50.0), np.minimum(k * zb, 50.0)
        ua = np.where(lo > 0, np.exp(ka), 0.0)
        ub = np.where(np.isinf(hi), np.inf, np.exp(kb))
        kw = k * np.log1p((hi - lo) / lo)
        mass, small = _weibull_log_mass(np.where(lo > 0, ka, -np.inf), np.where(np.isinf(hi), np.inf, kb), kw, lo > 0)
        # d log P / d(ln k) where D = ub - ua is taken in logs (the D/2 term is dropped)
        g_k_small = np.where((lo > 0) & np.isfinite(kw), kb + kw / np.expm1(kw), kb)
        za = np.where(k * za > 50.0, 0.0, za)
        zb = np.where(k * zb > 50.0, 0.0, zb)
        d = ub - ua
        inv = np.where(np.isinf(d), 0.0, 1.0 / np.expm1(d))
        # derivatives of u = (t/s)^k: du/dlnk = k z u, du/dlns = -k u (0 where u is 0 or inf)
        dua_k = np.where(ua > 0, k * za * ua, 0.0)
        dub_k = np.where(np.isfinite(ub) & (ub > 0), k * zb * ub, 0.0)
        dua_s, dub_s = -k * ua, np.where(np.isfinite(ub), -k * ub, 0.0)
        lp = np.where(exact, v[0] - ls + (k - 1.0) * za - ua, mass)
        g_k = np.where(exact, 1.0 + k * za - dua_k, np.where(small, -dua_k + g_k_small, -dua_k + (dub_k - dua_k) * inv))
        g_s = np.where(exact, -k + k * ua, np.where(small, -dua_s - k, -dua_s + (dub_s - dua_s) * inv))
    lp = np.where(np.isfinite(lp), lp, -1e6)
    tot = max(float(np.sum(wr)), 1e-300)
    f = -float(np.sum(wr * lp)) / tot
    g = -np.array([np.sum(wr * np.nan_to_num(g_k)), np.sum(wr * np.nan_to_num(g_s))]) / tot
    return f, g


def _weibull_mstep(lo: NDArray[np.float64], hi: NDArray[np.float64], wr: NDArray[np.float64], k0: float,
                   s0: float) -> tuple[float, float]:
    from scipy.optimize import minimize

    x0 = np.array([math.log(k0), math.log(s0)])
    f0 = _weibull_nll_grad(x0, lo, hi, wr)[0]
    res = minimize(_weibull_nll_grad, x0, args=(lo, hi, wr), jac=True, method="L-BFGS-B",
                   bounds=[(math.log(0.05), math.log(50.0)), (x0[1] - 20, x0[1] + 20)], options={"maxiter": 30})
    if res.fun < f0:
        return float(math.exp(res.x[0])), float(math.exp(res.x[1]))
    return k0, s0


# ---------------------------------------------------------------------------------- EM
def _lse_resp(v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Log-sum-exp over K (...) and responsibilities (..., K) from v = log pi_k + log P_k (..., K)."""
    m = np.max(v, axis=-1, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    lse = m[..., 0] + np.log(np.sum(np.exp(v - m), axis=-1))
    with np.errstate(invalid="ignore"):
        r = np.exp(v - lse[..., None])
    return lse, np.where(np.isfinite(r), r, 0.0)


def _mix_loglik(logp: NDArray[np.float64], logpi: NDArray[np.float64],
                w: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Weighted mixture log likelihood (...,) and responsibilities (..., n, K) from log P (..., n, K)."""
    lse, r = _lse_resp(logp + logpi[..., None, :])
    return np.sum(w * lse, axis=-1), r


def _row_correction(lo: NDArray[np.float64], hi: NDArray[np.float64], w: NDArray[np.float64], family: str) -> float:
    """Jacobian term making the log-normal exact-row densities densities of T (not of ln T)."""
    if family != "lognormal":
        return 0.0
    ex = lo == hi
    return -float(np.sum(w[ex] * np.log(lo[ex]))) if ex.any() else 0.0


class _Rows:
    """The rows of R runs laid end to end: run j owns ``lo[start[j]:start[j] + nrow[j]]`` (and hi, w)."""

    def __init__(self, lo: NDArray[np.float64], hi: NDArray[np.float64], w: NDArray[np.float64],
                 nrow: NDArray[np.intp]) -> None:
        self.lo, self.hi, self.w, self.nrow = lo, hi, w, nrow
        self.run = np.repeat(np.arange(nrow.size), nrow)
        self.start = np.concatenate([[0], np.cumsum(nrow)[:-1]]).astype(np.intp)

    def keep(self, runs: NDArray[np.bool_]) -> tuple[_Rows, NDArray[np.bool_]]:
        """The rows of the runs where ``runs`` is True, and the row mask that selects them."""
        rows = runs[self.run]
        return _Rows(self.lo[rows], self.hi[rows], self.w[rows], self.nrow[runs]), rows

    def sum(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per-run sums (R, ...) of per-row values (M, ...)."""
        return np.add.reduceat(x, self.start, axis=0)

    def slices(self) -> list[slice]:
        return [slice(a, a + n) for a, n in zip(self.start.tolist(), self.nrow.tolist())]


def _estep(family: str, rows: _Rows, p1: NDArray[np.float64], p2: NDArray[np.float64]
           ) -> tuple[NDArray[np.float64], tuple[NDArray[np.float64], ...]]:
    """(M, K) log P and the family's moments of every row under its run's parameters (R, K)."""
    if family == "lognormal":
        logp, ex, ex2 = _estep_lognormal(rows.lo, rows.hi, p1[rows.run], p2[rows.run])
        return logp, (ex, ex2)
    if family == "exponential":
        logp, et = _estep_exponential(rows.lo, rows.hi, p1[rows.run])
        return logp, (et,)
    logp = np.zeros((rows.lo.size, p1.shape[1]))
    for j, sl in enumerate(rows.slices()):
        logp[sl] = _weibull_logp(rows.lo[sl], rows.hi[sl], p1[j], p2[j])
    return logp, ()


def _mstep(family: str, rows: _Rows, r: NDArray[np.float64], mom: tuple[NDArray[np.float64], ...],
           pi: NDArray[np.float64], p1: NDArray[np.float64], p2: NDArray[np.float64],
           sigma_min: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One M-step of every run from its rows' responsibilities r (M, K) and moments."""
    wr = r * rows.w[:, None]
    nk = rows.sum(wr)
    live = nk > 1e-12
    pi = np.where(live, nk, 0.0) / nk.sum(axis=1, keepdims=True)
    nk_safe = np.where(live, nk, 1.0)
    if family == "lognormal":
        ex, ex2 = mom
        mu_new = rows.sum(wr * ex) / nk_safe
        dm = mu_new - p1
        var = rows.sum(wr * (ex2 - 2.0 * dm[rows.run] * (ex - p1[rows.run]))) / nk_safe + dm * dm
        return pi, np.where(live, mu_new, p1), np.where(live, np.maximum(np.sqrt(np.maximum(var, 0.0)), sigma_min), p2)
    if family == "exponential":
        return pi, np.where(live, nk_safe / np.maximum(rows.sum(wr * mom[0]), 1e-300), p1), p2
    p1, p2 = p1.copy(), p2.copy()
    for j, sl in enumerate(rows.slices()):
        for c in np.flatnonzero(live[j]).tolist():
            p1[j, c], p2[j, c] = _weibull_mstep(rows.lo[sl], rows.hi[sl], wr[sl, c], float(p1[j, c]), float(p2[j, c]))
    return pi, p1, p2


def _em_batch(family: str, rows: _Rows, corr: NDArray[np.float64], pi: NDArray[np.float64], p1: NDArray[np.float64],
              p2: NDArray[np.float64], sigma_min: float, max_iter: int, tol: float
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], list[list[float]]]:
    """R independent EM runs advanced together, each on its own rows; each stops when its own change is < tol.

    ``corr[j]`` is run j's :func:`_row_correction`. A run that stops leaves the batch (its parameters
    are those of its last E-step, as when it ran alone); a run still going after ``max_iter``
    iterations returns its parameters after the last M-step. Returns (pi, p1, p2) (R, K) and each
    run's trace.
    """
    out = [x.astype(np.float64).copy() for x in (pi, p1, p2)]
    pi, p1, p2 = (x.copy() for x in out)
    n_runs = pi.shape[0]
    hist = np.full((max(int(max_iter), 0), n_runs), np.nan)
    n_it = np.zeros(n_runs, dtype=np.intp)
    ids = np.arange(n_runs)
    prev = np.full(n_runs, np.nan)
    for it in range(max_iter):
        logp, mom = _estep(family, rows, p1, p2)
        with np.errstate(divide="ignore"):
            lse, r = _lse_resp(logp + np.log(pi)[rows.run])
        ll = rows.sum(rows.w * lse) + corr
        hist[it, ids] = ll
        n_it[ids] = it + 1
        stop = np.abs(ll - prev) < tol
        prev = ll
        if stop.any():
            for o, x in zip(out, (pi, p1, p2)):
                o[ids[stop]] = x[stop]
            keep = ~stop
            ids, corr, pi, p1, p2, prev = (x[keep] for x in (ids, corr, pi, p1, p2, prev))
            if not ids.size:
                break
            rows, sel = rows.keep(keep)
            r, mom = r[sel], tuple(x[sel] for x in mom)
        pi, p1, p2 = _mstep(family, rows, r, mom, pi, p1, p2, sigma_min)
    for o, x in zip(out, (pi, p1, p2)):
        o[ids] = x
    return out[0], out[1], out[2], [hist[:n, j].tolist() for j, n in enumerate(n_it.tolist())]


def em_intervals(family: str, lo: NDArray[np.float64], hi: NDArray[np.float64], w: NDArray[np.float64],
                 pi: NDArray[np.float64], p1: NDArray[np.float64], p2: NDArray[np.float64], *, sigma_min: float = 0.05,
                 max_iter: int = 250, tol: float = 1e-6) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                  NDArray[np.float64], list[float]]:
    """One EM run from the given start (rows as merged by :func:`fit_interval_mixture`).

    Returns (pi, p1, p2, log likelihood per iteration); the parameters are those of the last
    E-step, whose log likelihood is ``trace[-1]``.
    """
    corr = np.array([_row_correction(lo, hi, w, family)])
    rows = _Rows(lo, hi, w, np.array([lo.size], dtype=np.intp))
    a, b, c, tr = _em_batch(family, rows, corr, pi[None], p1[None], p2[None], sigma_min, max_iter, tol)
    return a[0], b[0], c[0], tr[0]


def interval_log_likelihood(mixture: SurvivalMixture, lo: ArrayLike, hi: ArrayLike,
                            weights: ArrayLike | None = None) -> float:
    """Weighted log likelihood of a mixture for interval-censored rows (exact rows: density of T)."""
    lo_, hi_, w = _prepare(lo, hi, weights)
    f = mixture.family
    if f == "lognormal":
        logp = _estep_lognormal(lo_, hi_, mixture.p1, mixture.p2)[0]
    elif f == "exponential":
        logp = _estep_exponential(lo_, hi_, mixture.p1)[0]
    elif f == "weibull":
        logp = _weibull_logp(lo_, hi_, mixture.p1, mixture.p2)
    else:
        raise EstimatorError(f"interval EM: family {f!r} not supported; valid: {', '.join(INTERVAL_FAMILIES)}")
    with np.errstate(divide="ignore"):
        ll, _ = _mix_loglik(logp, np.log(mixture.weights), w)
    return float(ll) + _row_correction(lo_, hi_, w, f)


def _point_guess(lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.float64]:
    with np.errstate(invalid="ignore"):
        g = np.where(np.isinf(hi), np.maximum(2.0 * lo, 1.0), np.where(lo > 0, np.sqrt(lo * hi), 0.5 * hi))
    return np.maximum(g, 1e-3)


def _wquantile(x: NDArray[np.float64], w: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    o = np.argsort(x)
    cw = np.cumsum(w[o])
    cw /= cw[-1]
    return np.interp(q, cw, x[o])


def _init(family: str, g: NDArray[np.float64], w: NDArray[np.float64], k: int, shift: NDArray[np.float64]
          ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    q = np.log(_wquantile(g, w, (np.arange(k) + 0.5) / k)) + shift
    pi = np.full(k, 1.0 / k)
    if family == "lognormal":
        return pi, q, np.ones(k)
    if family == "exponential":
        return pi, np.exp(-q), np.ones(k)
    return pi, np.ones(k), np.exp(q)


class _Problem:
    """One mixture fit in progress: its merged rows, restart generator and the best fit per K so far."""

    def __init__(self, lo: ArrayLike, hi: ArrayLike, weights: ArrayLike | None, max_components: int, family: str,
                 random_state: int) -> None:
        self.lo, self.hi, self.w = _prepare(lo, hi, weights)
        self.g = _point_guess(self.lo, self.hi)
        self.spread = max(float(np.std(np.log(self.g))), 0.1)
        self.rng = np.random.default_rng(random_state)
        self.k_max = max(1, min(int(max_components), self.lo.size))
        self.corr = _row_correction(self.lo, self.hi, self.w, family)
        self.best: IntervalFit | None = None
        self.aics: dict[int, float] = {}
        self.done = False

    def starts(self, family: str, k: int, n_restarts: int) -> list[tuple[NDArray[np.float64], ...]]:
        shifts = [np.zeros(k)] + [self.rng.normal(0.0, 0.5 * self.spread, k) for _ in range(n_restarts if k > 1 else 0)]
        return [_init(family, self.g, self.w, k, s) for s in shifts]

    def take(self, family: str, k: int, pis: NDArray[np.float64], p1s: NDArray[np.float64], p2s: NDArray[np.float64],
             traces: list[list[float]]) -> None:
        """Keep the best start of K = k; stop at the first K whose AIC does not improve on K - 1."""
        j = int(np.argmax([tr[-1] for tr in traces]))
        pi, p1, p2, trace = pis[j], p1s[j], p2s[j], traces[j]
        ll = trace[-1]
        aic = 2.0 * _N_PARAMS[family] * k - 2.0 * ll
        self.aics[k] = aic
        keep = pi >= 0.01
        scale = p2[keep] if family != "exponential" else np.ones(int(keep.sum()))
        mix = SurvivalMixture(family, pi[keep], p1[keep], scale)
        if self.best is None or aic < self.best.aic:
            self.best = IntervalFit(mix, ll, aic, self.aics, int(self.lo.size), float(self.w.sum()), trace)
        elif aic >= self.aics.get(k - 1, math.inf):  # AIC stopped improving: larger K are not tried
            self.done = True
        self.done = self.done or k >= self.k_max


def fit_interval_mixtures(problems: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike | None, int]], *,
                          family: str = "lognormal", sigma_min: float = 0.05, random_state: int = 0,
                          n_restarts: int = 2, max_iter: int = 250, tol: float = 1e-6) -> list[IntervalFit]:
    """:func:`fit_interval_mixture` of many independent problems, their EM runs advanced together.

    Args:
        problems: (lo, hi, weights, max_components) of each fit (as :func:`fit_interval_mixture`).
        family: as :func:`fit_interval_mixture`, shared by all problems.
        sigma_min: as :func:`fit_interval_mixture`.
        random_state: seed of each problem's own restart generator (a fit is the same alone or in a batch).
        n_restarts: as :func:`fit_interval_mixture`.
        max_iter: as :func:`fit_interval_mixture`.
        tol: as :func:`fit_interval_mixture`.

    Each K = 1, 2, ... runs all starts of every problem still selecting K as one padded batch (rows
    of different problems padded with weight-0 rows), which removes numpy's per-call cost of many
    small EMs; every run stops at the iteration where it would stop alone.

    Raises:
        EstimatorError: unknown family or a problem without usable intervals.
    """
    if family not in INTERVAL_FAMILIES:
        raise EstimatorError(f"interval EM: unknown family {family!r}; valid: {', '.join(INTERVAL_FAMILIES)}")
    probs = [_Problem(lo, hi, w, k, family, random_state) for lo, hi, w, k in problems]
    k = 1
    while True:
        todo = [p for p in probs if not p.done]
        if not todo:
            break
        inits = [p.starts(family, k, n_restarts) for p in todo]
        owner = np.repeat(np.arange(len(todo)), [len(x) for x in inits])
        runs = [todo[i] for i in owner.tolist()]
        rows = _Rows(np.concatenate([p.lo for p in runs]), np.concatenate([p.hi for p in runs]),
                     np.concatenate([p.w for p in runs]), np.array([p.lo.size for p in runs], dtype=np.intp))
        corr = np.array([p.corr for p in runs])
        pi0, p10, p20 = (np.stack([x[i] for run in inits for x in run]) for i in range(3))
        pis, p1s, p2s, traces = _em_batch(family, rows, corr, pi0, p10, p20, sigma_min, max_iter, tol)
        for i, p in enumerate(todo):
            sel = np.flatnonzero(owner == i)
            p.take(family, k, pis[sel], p1s[sel], p2s[sel], [traces[j] for j in sel.tolist()])
        k += 1
    out = []
    for p in probs:
        assert p.best is not None
        p.best.aic_by_k = p.aics
        out.append(p.best)
    return out


def fit_interval_mixture(lo: ArrayLike, hi: ArrayLike, *, family: str = "lognormal", weights: ArrayLike | None = None,
                         max_components: int = 5, sigma_min: float = 0.05, random_state: int = 0, n_restarts: int = 2,
                         max_iter: int = 250, tol: float = 1e-6) -> IntervalFit:
    """Fit a survival mixture to interval-censored durations; K = 1..max_components by AIC.

    Args:
        lo: (n,) lower bounds in seconds, ``0 <= lo <= hi``; rows with bad bounds are ignored.
        hi: (n,) upper bounds in seconds; ``hi = inf`` right-censored, ``lo == hi`` exact; rows with
            hi = 0 are ignored.
        family: "lognormal", "exponential" or "weibull".
        weights: (n,) positive row weights (default 1).
        max_components: largest K tried (capped at the number of distinct rows).
        sigma_min: floor of sigma of ln T (log-normal) to avoid components collapsing on one value.
        random_state: seed of the perturbed restarts (deterministic for a seed).
        n_restarts: extra starts per K with perturbed initial locations.
        max_iter: EM stops after this many iterations at most.
        tol: EM stops when the log likelihood changes by less than this.

    Raises:
        EstimatorError: unknown family or no usable interval.
    """
    return fit_interval_mixtures([(lo, hi, weights, max_components)], family=family, sigma_min=sigma_min,
                                 random_state=random_state, n_restarts=n_restarts, max_iter=max_iter, tol=tol)[0]
