"""Training from complete runs (the ``persistence_filter`` baseline; Perpetua and Perpetua* train on
interval-censored runs, :mod:`psg_data.estimators._survival_training`).

- :func:`segment_stream`: PELT change-point segmentation with a Bernoulli cost (minimum segment 5
  observations, penalty 3, as the Perpetua reference);
- :func:`runs_from_ground_truth` / :func:`runs_from_segments`: durations (s) of complete present
  runs and complete absent runs (the first and last runs are censored and dropped);
- :func:`fit_lognormal_mixture`: EM on ln T for K = 1..5 components, chosen by AIC (3K parameters),
  components with weight < 0.01 dropped, a few seeded restarts; deterministic for a seed;
- :func:`estimate_error_rates`: P_M and P_F from observations inside the segments.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._segmentation import segment_stream
from psg_data.estimators._survival import SurvivalMixture

__all__ = ["segment_stream", "runs_from_ground_truth", "runs_from_segments", "fit_lognormal_mixture",
           "estimate_error_rates", "EdgeDurations", "collect_durations", "MixtureFit"]

log = logging.getLogger(__name__)


def _complete_runs(starts: NDArray[np.float64], ends: NDArray[np.float64],
                   states: NDArray[np.int8]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Durations of complete present and absent runs (first and last runs are censored)."""
    d = ends - starts
    inner = slice(1, max(1, len(d) - 1))
    d, s = d[inner], states[inner]
    return d[s == 1], d[s == 0]


def runs_from_ground_truth(t_s: ArrayLike, state: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Complete present / absent run durations (s) of a dense ground-truth grid."""
    t = np.asarray(t_s, dtype=np.float64)
    x = np.asarray(state).astype(np.int8)
    if t.size < 2:
        return np.zeros(0), np.zeros(0)
    ch = np.flatnonzero(np.diff(x) != 0) + 1
    starts_i = np.concatenate([[0], ch])
    ends_i = np.concatenate([ch, [t.size - 1]])
    return _complete_runs(t[starts_i], t[ends_i], x[starts_i])


def runs_from_segments(t_s: ArrayLike, y: ArrayLike, bounds: NDArray[np.int64]) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.int8]]:
    """Run durations from a segmentation; adjacent segments with the same majority label are merged.

    A change time is taken halfway between the last observation of a run and the first of the next.

    Returns:
        present durations, absent durations, (N,) per-observation segment label.
    """
    t = np.asarray(t_s, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    lab = np.array([int(y[a:b].mean() >= 0.5) for a, b in zip(bounds[:-1], bounds[1:])], dtype=np.int8)
    per_obs = np.repeat(lab, np.diff(bounds)).astype(np.int8)
    if t.size == 0:
        return np.zeros(0), np.zeros(0), per_obs
    ch = np.flatnonzero(np.diff(per_obs) != 0) + 1
    if ch.size == 0:
        return np.zeros(0), np.zeros(0), per_obs
    cut = 0.5 * (t[ch - 1] + t[ch])
    starts = np.concatenate([[t[0]], cut])
    ends = np.concatenate([cut, [t[-1]]])
    states = per_obs[np.concatenate([[0], ch])]
    p, a = _complete_runs(starts, ends, states)
    return p, a, per_obs


@dataclass
class MixtureFit:
    """Result of :func:`fit_lognormal_mixture`."""

    mixture: SurvivalMixture
    log_likelihood: float
    aic: float
    aic_by_k: dict[int, float]


def _em_1d(x: NDArray[np.float64], k: int, mu0: NDArray[np.float64], sigma0: float, *, max_iter: int = 250,
           tol: float = 1e-6, sigma_min: float = 0.05) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                 NDArray[np.float64], float]:
    n = x.size
    pi = np.full(k, 1.0 / k)
    mu = mu0.astype(np.float64).copy()
    sd = np.full(k, float(sigma0))
    best = (pi.copy(), mu.copy(), sd.copy(), -np.inf)
    prev = -np.inf
    for _ in range(max_iter):
        lp = (np.log(np.maximum(pi, 1e-300)) - np.log(sd) - 0.5 * np.log(2 * np.pi)
              - 0.5 * ((x[:, None] - mu) / sd) ** 2)
        m = lp.max(axis=1, keepdims=True)
        lse = m[:, 0] + np.log(np.exp(lp - m).sum(axis=1))
        ll = float(lse.sum())
        if ll > best[3]:
            best = (pi.copy(), mu.copy(), sd.copy(), ll)
        if abs(ll - prev) < tol:
            break
        prev = ll
        r = np.exp(lp - lse[:, None])
        nk = r.sum(axis=0) + 1e-12
        pi = nk / n
        mu = (r * x[:, None]).sum(axis=0) / nk
        sd = np.sqrt((r * (x[:, None] - mu) ** 2).sum(axis=0) / nk)
        sd = np.maximum(sd, sigma_min)
    return best


def fit_lognormal_mixture(durations_s: ArrayLike, *, max_components: int = 5, random_state: int = 0,
                          n_restarts: int = 3, sigma_min: float = 0.05) -> MixtureFit:
    """Log-normal mixture for durations by EM on ln T, K chosen by AIC.

    Args:
        durations_s: (n,) positive durations in seconds.
        max_components: largest K tried (K = 1..max_components, capped at n).
        random_state: seed of the perturbed restarts.
        n_restarts: extra restarts per K with perturbed initial means.
        sigma_min: floor of sigma (of ln T) to avoid degenerate components.

    Returns:
        The mixture with the lowest AIC = 2 * 3K - 2 log L (log L of ln T, which differs from that of
        T by a constant), with components of weight < 0.01 dropped.
    """
    d = np.asarray(durations_s, dtype=np.float64).reshape(-1)
    d = d[np.isfinite(d) & (d > 0)]
    if d.size == 0:
        raise EstimatorError("fit_lognormal_mixture: no positive durations")
    x = np.log(d)
    rng = np.random.default_rng(random_state)
    spread = max(float(np.std(x)), 0.1)
    best: MixtureFit | None = None
    aics: dict[int, float] = {}
    for k in range(1, min(max_components, d.size) + 1):
        q = np.quantile(x, (np.arange(k) + 0.5) / k)
        runs = [_em_1d(x, k, q, 1.0, sigma_min=sigma_min)]
        for _ in range(n_restarts):
            runs.append(_em_1d(x, k, q + rng.normal(0, 0.5 * spread, k), 1.0, sigma_min=sigma_min))
        pi, mu, sd, ll = max(runs, key=lambda r: r[3])
        aic = 2 * 3 * k - 2 * ll
        aics[k] = aic
        keep = pi >= 0.01
        mix = SurvivalMixture("lognormal", pi[keep], mu[keep], sd[keep])
        if best is None or aic < best.aic:
            best = MixtureFit(mix, ll, aic, aics)
    assert best is not None
    best.aic_by_k = aics
    return best


def estimate_error_rates(y: ArrayLike, labels: ArrayLike, *, prior_count: float = 1.0) -> tuple[float, float]:
    """(P_M, P_F) = P(y=0 | label 1), P(y=1 | label 0) with a small pseudo-count, clipped to [1e-3, 0.45]."""
    y = np.asarray(y).astype(np.float64)
    lab = np.asarray(labels).astype(np.int8)
    pres, absn = y[lab == 1], y[lab == 0]
    pm = (np.sum(pres == 0) + 0.1 * prior_count) / (pres.size + prior_count)
    pf = (np.sum(absn == 1) + 0.1 * prior_count) / (absn.size + prior_count)
    return float(np.clip(pm, 1e-3, 0.45)), float(np.clip(pf, 1e-3, 0.45))


@dataclass
class EdgeDurations:
    present: NDArray[np.float64]
    absent: NDArray[np.float64]
    span_s: float
    mostly_present: bool


def collect_durations(streams: Sequence[EdgeStream], *, source: str = "segments", min_size: int = 5,
                      penalty: float = 3.0) -> tuple[dict[EdgeKey, EdgeDurations], tuple[float, float]]:
    """Per-edge run durations and pooled (P_M, P_F).

    Args:
        streams: training streams (ground truth, if used, in ``meta['gt_t_s']`` / ``meta['gt_state']``).
        source: "segments" (PELT on the observations), "ground_truth" (requires the meta keys) or
            "auto" (ground truth when present).
        min_size: minimum PELT segment length (observations).
        penalty: PELT change-point penalty.
    """
    if source not in ("segments", "ground_truth", "auto"):
        raise EstimatorError(f"durations source must be 'segments', 'ground_truth' or 'auto', got {source!r}")
    if int(min_size) < 1 or not float(penalty) >= 0:
        raise EstimatorError(f"segmentation: min_segment must be >= 1 and segment_penalty >= 0, got {min_size}, "
                             f"{penalty}")
    out: dict[EdgeKey, EdgeDurations] = {}
    ys, labs = [], []
    for s in streams:
        if len(s) == 0:
            continue
        has_gt = "gt_t_s" in s.meta and "gt_state" in s.meta
        if source == "ground_truth" and not has_gt:
            raise EstimatorError(f"edge {s.edge}: durations source 'ground_truth' needs meta['gt_t_s'] and "
                                 "meta['gt_state']")
        bounds = segment_stream(s.y, min_size=min_size, penalty=penalty)
        p, a, lab = runs_from_segments(s.t_s, s.y, bounds)
        if has_gt and source != "segments":
            gt_t = np.asarray(s.meta["gt_t_s"], dtype=np.float64)
            gt_x = np.asarray(s.meta["gt_state"]).astype(np.int8)
            p, a = runs_from_ground_truth(gt_t, gt_x)
            j = np.clip(np.searchsorted(gt_t, s.t_s, side="right") - 1, 0, gt_t.size - 1)
            lab = gt_x[j]
        ys.append(s.y)
        labs.append(lab)
        span = float(s.t_s[-1] - s.t_s[0])
        prev = out.get(s.edge)
        if prev is not None:  # several streams of one edge: pool
            p = np.concatenate([prev.present, p])
            a = np.concatenate([prev.absent, a])
            span = max(span, prev.span_s)
        out[s.edge] = EdgeDurations(p, a, span, bool(np.mean(lab) >= 0.5))
    if ys:
        pm, pf = estimate_error_rates(np.concatenate(ys), np.concatenate(labs))
    else:
        pm, pf = 0.1, 0.1
    return out, (pm, pf)
