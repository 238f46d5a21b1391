"""Detector error rates and a noise-aware segmentation from a pooled hidden Markov model.

On one edge alone a one-scan visit and a flipped observation look the same. Objects are on at most
one receptacle at a time, so each object is modelled jointly: its hidden state at a scan is
``z in {none, r_1, ..., r_K}`` (absent from every receptacle of the object, or on one of them), and
at that scan each observed edge k reports

    p(y_k = 1 | z = r_k) = 1 - P_M,        p(y_k = 1 | z != r_k) = P_F

(unobserved edges contribute nothing). Two seen-present edges at one time identify P_F; a
seen-absent scan inside a stay identifies P_M, because the dynamics are shared: at each step the
object stays where it is with probability ``s_c``, or else jumps to a receptacle (or to none)
drawn from its own destination distribution ``d_o`` (which may redraw the current state):

    A_c = s_c I + (1 - s_c) 1 d_o^T,       z_0 ~ d_o.

``c`` is the step kind: *same-day* steps and *long* (overnight) gaps have separate stay
probabilities; a step is long when its gap exceeds ``long_gap_factor`` times the typical (median)
gap of the training streams. P_M, P_F and s_c are pooled over all objects of a source; each
``d_o`` gets a Dirichlet pseudo-count (``prior_strength`` in all) toward uniform, so an object seen
a few times still has a proper destination distribution.

Baum-Welch (scaled forward-backward, all objects in one batch padded to the largest state space,
the jump indicator as a further latent variable so that every M-step is closed form) maximises the
penalised likelihood; it never decreases (tested). The per-edge posterior
``P(z_t = r_k | all observations)`` is the segmentation used for training: an observation is
taken as present where it is >= 0.5.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream, streams_by_edge

__all__ = ["HmmFit", "fit_error_hmm", "typical_gap_s"]

_RATE_MIN, _RATE_MAX = 1e-4, 0.45
_SCAN_FROM = 200  # longer sequences use the time-vectorised forward-backward


@dataclass
class _Batch:
    objects: list[str]
    edges: list[list[EdgeKey]]  # per object, its edges in state order 1..K
    times: list[NDArray[np.float64]]  # per object, its scan times
    y: NDArray[np.int8]  # (O, T, Kmax): 1, 0 or -1 (unobserved / padding)
    long: NDArray[np.bool_]  # (O, T): step t-1 -> t is a long gap
    valid_t: NDArray[np.bool_]  # (O, T): real time step
    n_states: NDArray[np.int64]  # (O,) K_o + 1


@dataclass
class HmmFit:
    """Result of :func:`fit_error_hmm`.

    Attributes:
        p_m, p_f: pooled detector error rates.
        stay: pooled probability that an object stays in its state over one step without
            jumping, per step kind ("same_day", "long_gap").
        long_gap_s: gaps longer than this (s) used the long-gap transitions.
        log_likelihood: penalised log likelihood per iteration.
        posterior: edge -> (t_s, P(present) at each of the edge's observation times).
        n_objects, n_steps: objects and object-scans in the model.
    """

    p_m: float
    p_f: float
    stay: dict[str, float]
    long_gap_s: float
    log_likelihood: list[float]
    posterior: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=dict)
    n_objects: int = 0
    n_steps: int = 0

    def summary(self) -> dict[str, float | int | dict[str, float]]:
        """The fitted rates and stay probabilities as plain numbers (for ``fit_summary_``)."""
        return {"p_m": self.p_m, "p_f": self.p_f, "stay": dict(self.stay), "long_gap_s": self.long_gap_s,
                "iterations": len(self.log_likelihood), "objects": self.n_objects, "object_steps": self.n_steps}


def typical_gap_s(streams: Sequence[EdgeStream]) -> float:
    """Median gap (s) between consecutive distinct observation times, pooled over streams (0: none)."""
    gaps = [np.diff(np.unique(s.t_s)) for s in streams if len(s) > 1]
    g = np.concatenate(gaps) if gaps else np.zeros(0)
    g = g[g > 0]
    return float(np.median(g)) if g.size else 0.0


def _batch(streams: Sequence[EdgeStream], long_gap_s: float) -> _Batch:
    by_obj: dict[str, dict[str, EdgeStream]] = {}
    for s in streams:
        if len(s):
            d = by_obj.setdefault(str(s.edge[0]), {})
            if s.edge[1] in d:  # several streams of one edge: merge
                old = d[s.edge[1]]
                t = np.concatenate([old.t_s, s.t_s])
                o = np.argsort(t, kind="stable")
                d[s.edge[1]] = EdgeStream(s.edge, t[o], np.concatenate([old.y, s.y])[o])
            else:
                d[s.edge[1]] = s
    objects = sorted(by_obj)
    if not objects:
        raise EstimatorError("error-rate HMM: no observations")
    times, edges = [], []
    for obj in objects:
        ss = [by_obj[obj][r] for r in sorted(by_obj[obj])]
        edges.append([s.edge for s in ss])
        times.append(np.unique(np.concatenate([s.t_s for s in ss])))
    n_obj, t_max = len(objects), max(t.size for t in times)
    k_max = max(len(e) for e in edges)
    y = np.full((n_obj, t_max, k_max), -1, dtype=np.int8)
    long = np.zeros((n_obj, t_max), dtype=bool)
    valid = np.zeros((n_obj, t_max), dtype=bool)
    for i, obj in enumerate(objects):
        tt = times[i]
        valid[i, :tt.size] = True
        long[i, 1:tt.size] = np.diff(tt) > long_gap_s
        for k, r in enumerate(sorted(by_obj[obj])):
            s = by_obj[obj][r]
            j = np.searchsorted(tt, s.t_s)
            y[i, j, k] = s.y  # a repeated time keeps its last observation
    return _Batch(objects, edges, times, y, long, valid, np.array([len(e) + 1 for e in edges], dtype=np.int64))


def _log_emissions(b: _Batch, p_m: float, p_f: float) -> NDArray[np.float64]:
    """(O, T, S) log p(y_t | z_t = s), s = 0 (none), 1..Kmax; padded states get -inf."""
    n_obj, t_max, k_max = b.y.shape
    l1 = np.where(b.y == 1, math.log(p_f), np.where(b.y == 0, math.log1p(-p_f), 0.0))  # edge k not the state
    base = l1.sum(axis=2)  # every observed edge as "not here"
    on1 = np.where(b.y == 1, math.log1p(-p_m), np.where(b.y == 0, math.log(p_m), 0.0))  # edge k is the state
    out = np.empty((n_obj, t_max, k_max + 1))
    out[:, :, 0] = base
    out[:, :, 1:] = base[:, :, None] - l1 + on1
    pad = np.arange(k_max + 1)[None, :] >= b.n_states[:, None]
    out[np.broadcast_to(pad[:, None, :], out.shape)] = -np.inf
    return out


def _forward_backward(le: NDArray[np.float64], a_same: NDArray[np.float64], a_long: NDArray[np.float64],
                      init: NDArray[np.float64], long: NDArray[np.bool_]) -> tuple[NDArray[np.float64], ...]:
    """Scaled forward-backward for all objects. Returns gamma (O,T,S), xi sums per kind (O,S,S) x2, loglik (O,)."""
    n_obj, t_max, n_s = le.shape
    m = le.max(axis=2, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    e = np.exp(le - m)
    alpha = np.empty((n_obj, t_max, n_s))
    c = np.empty((n_obj, t_max))
    a = init * e[:, 0]
    c[:, 0] = a.sum(axis=1)
    alpha[:, 0] = a / c[:, 0:1]
    for t in range(1, t_max):
        tr = np.where(long[:, t, None, None], a_long, a_same)
        a = np.einsum("os,osr->or", alpha[:, t - 1], tr) * e[:, t]
        c[:, t] = a.sum(axis=1)
        alpha[:, t] = a / c[:, t:t + 1]
    beta = np.ones((n_obj, t_max, n_s))
    xi_same = np.zeros((n_obj, n_s, n_s))
    xi_long = np.zeros((n_obj, n_s, n_s))
    for t in range(t_max - 1, 0, -1):
        tr = np.where(long[:, t, None, None], a_long, a_same)
        be = beta[:, t] * e[:, t]
        beta[:, t - 1] = np.einsum("osr,or->os", tr, be) / c[:, t:t + 1]
        x = alpha[:, t - 1, :, None] * tr * be[:, None, :] / c[:, t, None, None]
        lg = long[:, t, None, None]
        xi_long += np.where(lg, x, 0.0)
        xi_same += np.where(lg, 0.0, x)
    gamma = alpha * beta
    gamma /= np.maximum(gamma.sum(axis=2, keepdims=True), 1e-300)
    loglik = np.log(c).sum(axis=1) + m[:, :, 0].sum(axis=1)
    return gamma, xi_same, xi_long, loglik


def _prefix_products(m: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inclusive prefix products P_t = M_0 @ ... @ M_t of (O, T, S, S) matrices by recursive doubling.

    Each stored product is scaled by its largest entry; the log of the scale is returned (O, T), so
    that products over tens of thousands of steps neither overflow nor underflow.
    """
    n_obj, n_t, n_s, _ = m.shape

    def scale(x: NDArray[np.float64]) -> NDArray[np.float64]:
        flat = x.reshape(x.shape[0], x.shape[1], n_s * n_s)
        if n_s > 3:  # a reduction over the S * S entries (measured faster from S = 4 on)
            mx = flat.max(axis=2)
        else:  # elementwise: much faster than a reduction over a tiny axis
            mx = flat[:, :, 0].copy()
            for j in range(1, n_s * n_s):
                np.maximum(mx, flat[:, :, j], out=mx)
        np.maximum(mx, 1e-300, out=mx)
        x /= mx[:, :, None, None]
        return np.log(mx)

    def matmul(a: NDArray[np.float64], b: NDArray[np.float64], out: NDArray[np.float64]) -> NDArray[np.float64]:
        if n_s > 3:
            return np.matmul(a, b, out=out)
        out[...] = 0.0
        for i in range(n_s):
            for k in range(n_s):
                for j in range(n_s):
                    out[..., i, k] += a[..., i, j] * b[..., j, k]
        return out

    p = m.copy()
    nxt = np.empty_like(p)  # each pass writes its products here, then the two swap (no copy of the T - d new ones)
    c = scale(p)
    d = 1
    while d < n_t:
        q = matmul(p[:, :-d], p[:, d:], nxt[:, d:])
        cq = scale(q)
        nxt[:, :d] = p[:, :d]
        p, nxt = nxt, p
        c[:, d:] += c[:, :-d].copy() + cq
        d *= 2
    return p, c


def _forward_backward_scan(le: NDArray[np.float64], a_same: NDArray[np.float64], a_long: NDArray[np.float64],
                           init: NDArray[np.float64], long: NDArray[np.bool_]) -> tuple[NDArray[np.float64], ...]:
    """:func:`_forward_backward` vectorised over time (prefix / suffix matrix products, O(T log T))."""
    n_obj, t_max, n_s = le.shape
    mle = le.max(axis=2, keepdims=True)
    mle = np.where(np.isfinite(mle), mle, 0.0)
    e = np.exp(le - mle)  # (O, T, S)
    tr = np.where(long[:, :, None, None], a_long[:, None], a_same[:, None])  # (O, T, S, S): step t-1 -> t
    m = tr * e[:, :, None, :]  # M_t = A_t diag(e_t)
    m[:, 0] = np.eye(n_s)[None] * e[:, 0, None, :]  # the first step has no transition
    pf, cf = _prefix_products(m)
    alpha = np.einsum("os,otsr->otr", init, pf)
    sa = alpha.sum(axis=2)
    alpha /= np.maximum(sa, 1e-300)[:, :, None]
    loglik = np.log(sa[:, -1]) + cf[:, -1] + mle[:, :, 0].sum(axis=1)
    # backward: beta_t = M_{t+1} ... M_{T-1} 1, from prefix products of the reversed, transposed chain
    rev = np.swapaxes(m[:, :0:-1], 2, 3)  # M_{T-1}^T, ..., M_1^T
    pb, _ = _prefix_products(rev) if t_max > 1 else (np.zeros((n_obj, 0, n_s, n_s)), None)
    beta = np.ones((n_obj, t_max, n_s))
    if t_max > 1:
        beta[:, :-1] = pb.sum(axis=2)[:, ::-1]  # column sums of (M_{t+1} ... M_{T-1})^T = that product @ 1
        beta[:, :-1] /= np.maximum(beta[:, :-1].max(axis=2, keepdims=True), 1e-300)
    gamma = alpha * beta
    gamma /= np.maximum(gamma.sum(axis=2, keepdims=True), 1e-300)
    x = alpha[:, :-1, :, None] * m[:, 1:] * beta[:, 1:, None, :]  # (O, T-1, S, S)
    x /= np.maximum(x.sum(axis=(2, 3), keepdims=True), 1e-300)
    lg = long[:, 1:, None, None]
    xi_long = np.where(lg, x, 0.0).sum(axis=1)
    xi_same = np.where(lg, 0.0, x).sum(axis=1)
    return gamma, xi_same, xi_long, loglik


def _transitions(stay: float, d: NDArray[np.float64]) -> NDArray[np.float64]:
    """(O, S, S) A = stay I + (1 - stay) 1 d^T (padded states have d = 0)."""
    n_s = d.shape[1]
    return stay * np.eye(n_s)[None] + (1.0 - stay) * np.broadcast_to(d[:, None, :], (d.shape[0], n_s, n_s))


def fit_error_hmm(streams: Sequence[EdgeStream], *, p_m: float | None = None, p_f: float | None = None,
                  long_gap_factor: float = 3.0, prior_strength: float = 2.0, max_iter: int = 200,
                  tol: float = 1e-6) -> HmmFit:
    """Fit the pooled multi-receptacle HMM to training streams (see the module docstring).

    Args:
        streams: observations per edge (object id = ``edge[0]``); times in s.
        p_m: fix the missed-detection rate P_M instead of estimating it.
        p_f: fix the false-positive rate P_F instead of estimating it.
        long_gap_factor: a gap longer than this many typical gaps uses the long-gap transitions.
        prior_strength: Dirichlet pseudo-count (in all, per object) of the destination
            distribution toward uniform.
        max_iter: Baum-Welch stops after this many iterations at most.
        tol: Baum-Welch stops when the penalised log likelihood changes by less than this.

    Returns:
        :class:`HmmFit` with the rates, the pooled stay probabilities and per-edge posteriors.
    """
    typ = typical_gap_s(streams)
    long_gap_s = long_gap_factor * typ if typ > 0 else math.inf
    b = _batch(streams, long_gap_s)
    n_obj, t_max, k_max = b.y.shape
    n_s = k_max + 1
    mask = np.arange(n_s)[None, :] < b.n_states[:, None]
    pm = 0.05 if p_m is None else float(np.clip(p_m, 1e-9, 0.499))
    pf = 0.05 if p_f is None else float(np.clip(p_f, 1e-9, 0.499))
    stay = {"same_day": 0.7, "long_gap": 0.5}
    d = mask / mask.sum(axis=1, keepdims=True)
    alpha_d = prior_strength * mask / mask.sum(axis=1, keepdims=True)
    long = b.long & b.valid_t
    trace: list[float] = []
    gamma = None
    for _ in range(max_iter):
        le = _log_emissions(b, pm, pf)
        le = np.where(b.valid_t[:, :, None], le, np.where(mask[:, None, :], 0.0, -np.inf))
        fb = _forward_backward_scan if t_max > _SCAN_FROM else _forward_backward
        gamma, xs, xl, ll = fb(le, _transitions(stay["same_day"], d), _transitions(stay["long_gap"], d), d, long)
        with np.errstate(divide="ignore", invalid="ignore"):
            pen = float(np.sum(np.where(mask, alpha_d * np.log(d), 0.0)))
        total = float(ll.sum()) + pen
        done = bool(trace) and abs(total - trace[-1]) < tol * max(1.0, abs(total))
        trace.append(total)
        if done:
            break
        # error rates from expected counts over the observed (object, time, edge) cells
        g_on = gamma[:, :, 1:]  # (O, T, Kmax): P(z = r_k)
        obs = b.y >= 0
        if p_m is None:
            den = float(np.sum(g_on * obs))
            pm = float(np.clip(np.sum(g_on * (b.y == 0)) / den, _RATE_MIN, _RATE_MAX)) if den > 0 else pm
        if p_f is None:
            den = float(np.sum((1 - g_on) * obs))
            pf = float(np.clip(np.sum((1 - g_on) * (b.y == 1)) / den, _RATE_MIN, _RATE_MAX)) if den > 0 else pf
        # stays and destinations: split each i -> i transition into "stayed" and "jumped and redrew i"
        land = gamma[:, 0].copy()
        for kind, xi in (("same_day", xs), ("long_gap", xl)):
            s_c = stay[kind]
            dg = np.diagonal(xi, axis1=1, axis2=2)
            with np.errstate(invalid="ignore", divide="ignore"):
                pj = np.where(mask, (1 - s_c) * d / (s_c + (1 - s_c) * d), 0.0)
            jumps_in = xi.sum(axis=1) - dg + dg * pj  # (O, S) jumps landing on each state
            n_tot = float(np.sum(xi))
            if n_tot > 0:
                stay[kind] = float(np.clip(1.0 - jumps_in.sum() / n_tot, 1e-3, 1 - 1e-6))
            land += jumps_in
        d = (land + alpha_d) * mask
        d /= d.sum(axis=1, keepdims=True)
    assert gamma is not None
    post: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    by_edge = streams_by_edge(streams)
    for i, es in enumerate(b.edges):
        tt = b.times[i]
        for k, e in enumerate(es):
            ts = np.concatenate([s.t_s for s in by_edge[e]])
            ts.sort(kind="stable")
            post[e] = (ts, gamma[i, np.searchsorted(tt, ts), k + 1])
    return HmmFit(pm, pf, stay, long_gap_s, trace, post, n_obj, int(b.valid_t.sum()))
