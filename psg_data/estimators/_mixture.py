"""Mixtures of persistence filters and of emergence filters (paper eqs. 1-8), vectorised in log space.

The persistence filter (Rosen et al. 2016) recursion for observations y_1..y_N at times t_1..t_N
(measured from the filter's origin) is, per mixture component l::

    l_N  = l_{N-1} + log p(y_N | present)
    LY_N = log p(y_N | absent) + logaddexp(LY_{N-1}, l_{N-1} + log(S_l(t_{N-1}) - S_l(t_N)))
    E_N  = logaddexp(LY_N, l_N + log S_l(t_N))              # log p(Y_1:N | c_l)
    p(present at t >= t_N | c_l, Y) = exp(l_N + log S_l(t) - E_N)

With B_i the cumulative sum of log p(y_i | absent), ``LY_N - B_N`` is a cumulative log-sum-exp of
``l_{i-1} - B_{i-1} + log(S(t_{i-1}) - S(t_i))``, so a batch of observations costs a handful of
vectorised passes (``np.logaddexp.accumulate``) instead of a Python loop.

An emergence filter is a persistence filter on the *absence* state with the error model swapped
(P_M' = 1 - P_F, P_F' = 1 - P_M); its prediction of presence is 1 - P(absence persists).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._survival import SurvivalMixture, log_sub_exp

__all__ = ["MixtureFilter", "ScanResult", "clip_error_rate", "encode_floats", "decode_floats"]


def encode_floats(a: ArrayLike) -> list[float | None]:
    """JSON-safe list: -inf becomes None (log 0); other values must be finite."""
    return [None if v == -np.inf else float(v) for v in np.asarray(a, dtype=np.float64).reshape(-1)]


def decode_floats(v: list[float | None]) -> NDArray[np.float64]:
    return np.array([-np.inf if x is None else x for x in v], dtype=np.float64)

_EPS_RATE = 1e-9


def clip_error_rate(p: float, name: str) -> float:
    """Validate a detector error rate and keep it away from 0 (log 0)."""
    p = float(p)
    if not (0.0 <= p < 0.5):
        raise EstimatorError(f"{name} must be in [0, 0.5), got {p}")
    return max(p, _EPS_RATE)


@dataclass
class ScanResult:
    """Per-observation quantities of a batch scan (no state change). Shapes: (n,) or (n, K)."""

    t: NDArray[np.float64]  # absolute times
    l: NDArray[np.float64]
    ly: NDArray[np.float64]
    lsf: NDArray[np.float64]
    e: NDArray[np.float64]  # per-component log evidence
    log_evidence: NDArray[np.float64]  # mixture log evidence (with log prior weights)
    dominant: NDArray[np.intp]
    p_own: NDArray[np.float64]  # P(own "present" state at t_i | Y_1:i, dominant component)


class MixtureFilter:
    """A mixture of persistence filters (or of emergence filters) sharing one likelihood term.

    Args:
        survival: the survival prior of the filtered state's duration.
        p_m: P(y = 0 | feature present) (missed detection).
        p_f: P(y = 1 | feature absent) (false positive).
        emergence: if True, filter the absence state (emergence filter); predictions are still
            P(feature present).
        log_prior: optional (K,) log component weights overriding ``survival.weights`` (Perpetua
            resets mix the previous posterior into them).

    The origin (time 0 of the survival prior) is the first observation time unless ``start`` is
    called. Before any observation a persistence mixture predicts its prior survival and an
    emergence mixture predicts 0 (never started).
    """

    def __init__(self, survival: SurvivalMixture, p_m: float, p_f: float, *, emergence: bool = False,
                 log_prior: NDArray[np.float64] | None = None) -> None:
        self.survival = survival
        self.p_m = clip_error_rate(p_m, "p_m")
        self.p_f = clip_error_rate(p_f, "p_f")
        self.emergence = bool(emergence)
        k = survival.n_components
        self.log_prior = (survival.log_weights.copy() if log_prior is None
                          else np.asarray(log_prior, dtype=np.float64).copy())
        if self.log_prior.shape != (k,):
            raise EstimatorError(f"log_prior must have shape ({k},), got {self.log_prior.shape}")
        # log p(y | own state present) for y = 0, 1 and log p(y | own state absent)
        lpres = np.log([self.p_m, 1.0 - self.p_m])
        labs = np.log([1.0 - self.p_f, self.p_f])
        self._la, self._lb = (labs, lpres) if self.emergence else (lpres, labs)
        self.reset(None)

    # ------------------------------------------------------------------ state
    def reset(self, origin: float | None) -> None:
        """Forget all observations; survival time 0 is ``origin`` (None: the next observation)."""
        k = self.survival.n_components
        self.origin = None if origin is None else float(origin)
        self.n = 0
        self.l = 0.0
        self.ly = np.full(k, -np.inf)
        self.tau = 0.0
        self.lsf = np.zeros(k)
        self.last_t: float | None = None

    @property
    def started(self) -> bool:
        return self.origin is not None

    def component_log_evidence(self) -> NDArray[np.float64]:
        """(K,) log p(Y | c_l)."""
        return np.logaddexp(self.ly, self.l + self.lsf)

    def log_evidence(self) -> float:
        """log p(Y) of the mixture (0 before any observation)."""
        v = self.log_prior + self.component_log_evidence()
        m = np.max(v)
        return float(m + np.log(np.sum(np.exp(v - m))))

    def posterior_weights(self) -> NDArray[np.float64]:
        """(K,) w_l = p(c_l | Y) (eq. 7); sums to 1."""
        v = self.log_prior + self.component_log_evidence()
        w = np.exp(v - np.max(v))
        return w / w.sum()

    def dominant(self) -> int:
        return int(np.argmax(self.log_prior + self.component_log_evidence()))

    # ------------------------------------------------------------------ batch scan
    def scan(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> ScanResult:
        """Run the recursion over a batch without changing the state."""
        t = np.asarray(t, dtype=np.float64)
        yi = np.asarray(y).astype(np.intp)
        n = t.size
        origin = float(t[0]) if (self.origin is None and n) else (self.origin if self.origin is not None else 0.0)
        tau = np.maximum(t - origin, self.tau)
        lsf = self.survival.log_sf(tau)  # (n, K)
        lsf_prev = np.concatenate([self.lsf[None, :], lsf[:-1]], axis=0)
        logdelta = log_sub_exp(lsf_prev, lsf)
        a = self._la[yi]
        b = self._lb[yi]
        l = self.l + np.cumsum(a)
        bc = np.cumsum(b)
        l_prev = np.concatenate([[self.l], l[:-1]])
        bc_prev = np.concatenate([[0.0], bc[:-1]])
        x = np.empty((n + 1, lsf.shape[1]))
        x[0] = self.ly
        x[1:] = (l_prev - bc_prev)[:, None] + logdelta
        z = np.logaddexp.accumulate(x.T, axis=1).T[1:]
        ly = z + bc[:, None]
        e = np.logaddexp(ly, l[:, None] + lsf)
        v = e + self.log_prior
        dom = np.argmax(v, axis=1)
        m = v[np.arange(n), dom]
        log_ev = m + np.log(np.sum(np.exp(v - m[:, None]), axis=1))
        idx = np.arange(n)
        p_own = np.exp(np.minimum(l + lsf[idx, dom] - e[idx, dom], 0.0))
        return ScanResult(t, l, ly, lsf, e, log_ev, dom, p_own)

    def commit(self, res: ScanResult, i: int) -> None:
        """Set the state to the one after observation ``i`` of a scan."""
        if self.origin is None:
            self.origin = float(res.t[0])
        self.n += i + 1
        self.l = float(res.l[i])
        self.ly = res.ly[i].copy()
        self.lsf = res.lsf[i].copy()
        self.tau = max(float(res.t[i]) - self.origin, self.tau)
        self.last_t = float(res.t[i])

    def update_many(self, t: ArrayLike, y: ArrayLike, chunk: int = 65536) -> None:
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        y = np.asarray(y).reshape(-1)
        for s in range(0, t.size, chunk):
            res = self.scan(t[s:s + chunk], y[s:s + chunk])
            self.commit(res, res.t.size - 1)

    def update(self, t: float, y: int) -> None:
        self.update_many(np.array([t]), np.array([y]))

    # ------------------------------------------------------------------ prediction
    def predict_own(self, t: ArrayLike) -> NDArray[np.float64]:
        """P(own state still holds at t | Y, dominant component) for t >= last observation (eq. 8)."""
        t = np.asarray(t, dtype=np.float64)
        if self.origin is None:
            return np.ones_like(t)
        k = self.dominant()
        e = float(self.component_log_evidence()[k])
        tau = np.maximum(t - self.origin, self.tau)
        return np.exp(np.minimum(self.l + self.survival.log_sf_one(tau, k) - e, 0.0))

    def predict(self, t: ArrayLike) -> NDArray[np.float64]:
        """P(feature present at t). An emergence mixture that was never started predicts 0."""
        t = np.asarray(t, dtype=np.float64)
        if self.emergence:
            if self.origin is None:
                return np.zeros_like(t)
            return 1.0 - self.predict_own(t)
        return self.predict_own(t)

    # ------------------------------------------------------------------ serialisation
    def get_state(self) -> dict[str, Any]:
        return {"origin": self.origin, "n": self.n, "l": self.l, "ly": encode_floats(self.ly), "tau": self.tau,
                "lsf": encode_floats(self.lsf), "last_t": self.last_t, "log_prior": encode_floats(self.log_prior)}

    def set_state(self, s: dict[str, Any]) -> None:
        self.origin = s["origin"]
        self.n = int(s["n"])
        self.l = float(s["l"])
        self.ly = decode_floats(s["ly"])
        self.tau = float(s["tau"])
        self.lsf = decode_floats(s["lsf"])
        self.last_t = s["last_t"]
        self.log_prior = decode_floats(s["log_prior"])
