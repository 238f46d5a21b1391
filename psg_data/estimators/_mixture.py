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

Escape floor. The probability that the state changed inside an interval, ``S(t_{i-1}) - S(t_i)``,
is floored at ``escape`` (default 1e-10), and at ``escape_first`` (1e-6) for the interval ending
at the first observation after a (re)start (the mass "changed before the first observation").
Without it a filter whose survival prior is narrow (a log-normal with sigma of ln T of 0.005-0.07,
as fitted on dense, regular streams) gives zero probability to a change before the prior's lower
tail and ignores any number of contrary observations until then. The public reference gets the
same floors from clipping survival probabilities to [1e-10, 0.999999] in float32. With the floor
the component evidences are no longer exact probabilities of a proper model; ``escape=0``
restores the exact recursion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._survival import SurvivalMixture

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
    """Per-observation quantities of a batch scan (no state change).

    Per-component arrays are (K, n) (component-major: reductions over components are elementwise
    operations on K rows); the others are (n,).
    """

    t: NDArray[np.float64]  # absolute times
    tau: NDArray[np.float64]  # survival time since the origin
    l: NDArray[np.float64]
    ly: NDArray[np.float64]  # (K, n)
    lsf: NDArray[np.float64]  # (K, n)
    log_evidence: NDArray[np.float64]  # mixture log evidence (with log prior weights)
    p_own: NDArray[np.float64]  # P(own state still holds at t_i | Y_1:i, dominant component)
    origin: float


_NEG_INF = -math.inf
ESCAPE = 1e-10
"""Default floor of the change probability per interval (see the module docstring)."""
ESCAPE_FIRST = 1e-6
"""Default floor of the change probability before the first observation after a (re)start."""


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

    State: ``l`` (float), ``ly`` and ``lsf`` (lists of K floats: the one-at-a-time path works on
    Python floats, see :meth:`step`), ``tau``, ``origin``, ``n``, ``last_t``. Batches go through
    the vectorised :meth:`scan` (numpy, component-major), single observations through the scalar
    :meth:`step` (math module); both implement the same recursion and agree to rounding.
    """

    def __init__(self, survival: SurvivalMixture, p_m: float, p_f: float, *, emergence: bool = False,
                 log_prior: NDArray[np.float64] | None = None, escape: float = ESCAPE,
                 escape_first: float = ESCAPE_FIRST) -> None:
        if not (0.0 <= escape <= 1e-3 and 0.0 <= escape_first <= 1e-3):
            raise EstimatorError(f"escape floors must be in [0, 1e-3], got {escape}, {escape_first}")
        self.escape = float(escape)
        self.escape_first = float(escape_first)
        self._log_esc = math.log(escape) if escape > 0 else _NEG_INF
        self._log_esc1 = math.log(escape_first) if escape_first > 0 else _NEG_INF
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
        self._la_s, self._lb_s = self._la.tolist(), self._lb.tolist()
        self.reset(None)

    @property
    def log_prior(self) -> NDArray[np.float64]:
        """Log prior weights of the mixture components (natural log)."""
        return self._log_prior

    @log_prior.setter
    def log_prior(self, v: ArrayLike) -> None:
        self._log_prior = np.asarray(v, dtype=np.float64)
        self._log_prior_s = self._log_prior.tolist()

    # ------------------------------------------------------------------ state
    def reset(self, origin: float | None) -> None:
        """Forget all observations; survival time 0 is ``origin`` (None: the next observation)."""
        k = self.survival.n_components
        self.origin = None if origin is None else float(origin)
        self.n = 0
        self.l = 0.0
        self.ly: list[float] = [_NEG_INF] * k
        self.tau = 0.0
        self.lsf: list[float] = [0.0] * k
        self.last_t: float | None = None
        self._dom: tuple[list[float], list[float], NDArray[np.float64], float, int, float] | None = None

    @property
    def started(self) -> bool:
        """Whether the survival clock has an origin (given to :meth:`reset` or set by the next observation)."""
        return self.origin is not None

    def component_log_evidence(self) -> NDArray[np.float64]:
        """(K,) log p(Y | c_l)."""
        return np.logaddexp(np.asarray(self.ly, dtype=np.float64), self.l + np.asarray(self.lsf, dtype=np.float64))

    def log_evidence(self) -> float:
        """Log p(Y) of the mixture (0 before any observation)."""
        v = self.log_prior + self.component_log_evidence()
        m = np.max(v)
        return float(m + np.log(np.sum(np.exp(v - m))))

    def posterior_weights(self) -> NDArray[np.float64]:
        """(K,) w_l = p(c_l | Y) (eq. 7); sums to 1."""
        v = self.log_prior + self.component_log_evidence()
        w = np.exp(v - np.max(v))
        return w / w.sum()

    def dominant(self) -> int:
        """Index of the component with the largest posterior weight."""
        return int(np.argmax(self.log_prior + self.component_log_evidence()))

    def dominant_evidence(self) -> tuple[int, float]:
        """(:meth:`dominant`, its :meth:`component_log_evidence`): the values :meth:`step` computed on
        floats when the state is still the one it left (the same operations: ``logaddexp``'s cases,
        the first largest weight), else computed here.
        """
        d = self._dom
        if d is not None and d[0] is self.ly and d[1] is self.lsf and d[2] is self._log_prior and d[3] == self.l:
            return d[4], d[5]
        cle = self.component_log_evidence()
        k = int(np.argmax(self.log_prior + cle))
        return k, float(cle[k])

    # ------------------------------------------------------------------ batch scan
    def scan(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> ScanResult:
        """Run the recursion over a batch from the current state without changing it."""
        t = np.asarray(t, dtype=np.float64)
        origin = self.origin if self.origin is not None else (float(t[0]) if t.size else 0.0)
        return self.scan_from(origin, self.tau, self.l, self.ly, self.lsf, t, np.asarray(y).astype(np.intp))

    def scan_from(self, origin: float, tau0: float, l0: float, ly0: ArrayLike | None, lsf0: ArrayLike | None,
                  t: NDArray[np.float64], yi: NDArray[np.intp]) -> ScanResult:
        """The recursion over a batch from an explicit state (origin, tau, l, ly, lsf); pure.

        ``ly0 = lsf0 = None`` is the fresh state (no observation yet: LY = -inf, log S = 0).

        With B_i = sum_{j<=i} log p(y_j | absent) and u_{i-1} = l_{i-1} - B_{i-1}:
        LY_i = B_i + logcumsumexp_j(u_{j-1} + log(S(t_{j-1}) - S(t_j))) (a single accumulate), and
        log(S_prev - S) = lsf_prev + log(-expm1(lsf - lsf_prev)).
        """
        n = t.size
        lp = self._log_prior
        k = lp.size
        tau = t - origin
        np.maximum(tau, tau0, out=tau)
        lsf = self.survival.log_sf_rows(tau)  # (K, n)
        x = np.empty((k, n + 1))
        x[:, 0] = _NEG_INF if ly0 is None else ly0
        d = x[:, 1:]
        prev = np.empty((k, n))
        prev[:, 0] = 0.0 if lsf0 is None else lsf0
        prev[:, 1:] = lsf[:, :-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            np.subtract(lsf, prev, out=d)
            np.expm1(d, out=d)
            np.negative(d, out=d)
            np.log(d, out=d)
            d += prev
        np.fmax(d, _NEG_INF, out=d)  # nan (both survivals 0) -> log 0
        first = d[:, 0].copy()
        np.maximum(d, self._log_esc, out=d)  # escape floor
        if ly0 is None or np.all(np.isneginf(np.asarray(ly0, dtype=np.float64))):  # fresh: nothing filtered yet
            np.maximum(first, self._log_esc1, out=d[:, 0])  # escape_first instead of escape, as in step
        ca = self._la[yi]
        np.cumsum(ca, out=ca)
        l = ca
        l += l0
        cb = self._lb[yi]
        np.cumsum(cb, out=cb)
        u = np.empty(n)
        u[0] = l0
        np.subtract(l[:-1], cb[:-1], out=u[1:])
        d += u
        np.logaddexp.accumulate(x, axis=1, out=x)
        ly = x[:, 1:]
        ly += cb
        e = lsf + l
        np.logaddexp(ly, e, out=e)
        if k == 1:
            ev = e[0] + lp[0]
            p_own = np.minimum(l + lsf[0] - e[0], 0.0)
        else:
            v = e + lp[:, None]
            dom = np.argmax(v, axis=0)
            cols = np.arange(n)
            m = v[dom, cols]
            v -= m
            np.exp(v, out=v)
            ev = np.log(v.sum(axis=0))
            ev += m
            p_own = np.minimum(l + lsf[dom, cols] - e[dom, cols], 0.0)
        np.exp(p_own, out=p_own)
        return ScanResult(t, tau, l, ly, lsf, ev, p_own, origin)

    def commit(self, res: ScanResult, i: int) -> None:
        """Set the state to the one after observation ``i`` of a scan (counted from the current state)."""
        self.origin = res.origin
        self.n += i + 1
        self.l = float(res.l[i])
        self.ly = res.ly[:, i].tolist()
        self.lsf = res.lsf[:, i].tolist()
        self.tau = float(res.tau[i])
        self.last_t = float(res.t[i])

    def update_many(self, t: ArrayLike, y: ArrayLike, chunk: int = 65536) -> None:
        """Apply observations in time order, vectorised ``chunk`` at a time; equal to :meth:`update` per one."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        y = np.asarray(y).reshape(-1)
        for s in range(0, t.size, chunk):
            res = self.scan(t[s:s + chunk], y[s:s + chunk])
            self.commit(res, res.t.size - 1)

    # ------------------------------------------------------------------ one observation
    def step(self, t: float, y: int) -> tuple[float, float]:
        """Update with one observation in plain Python floats; return (log evidence, p_own).

        The same recursion as :meth:`scan` (``LY = log p(y|absent) + logaddexp(LY, l_prev +
        log(S_prev - S))``), O(K) math-module calls, no numpy: for the handful of components used
        in practice this is ~10x faster than a one-row scan.
        """
        if self.origin is None:
            self.origin = float(t)
        tau = t - self.origin
        if tau < self.tau:
            tau = self.tau
        lsf = self.survival.log_sf_scalar(tau)
        l_prev = self.l
        l = l_prev + self._la_s[y]
        b = self._lb_s[y]
        log, expm1, exp, log1p = math.log, math.expm1, math.exp, math.log1p
        ninf = _NEG_INF
        ly = []
        vs = []
        best, bi, ebest = ninf, 0, ninf
        esc = self._log_esc1 if self.n == 0 else self._log_esc
        for i, (lp, so, sn, a0) in enumerate(zip(self._log_prior_s, self.lsf, lsf, self.ly)):
            dd = sn - so
            # log(S_prev - S), floored at the escape probability
            x = so + log(-expm1(dd)) if dd < 0.0 else ninf
            if x < esc:
                x = esc
            if x == ninf:  # no change possible in this interval
                v = b + a0
            else:  # LY = b + logaddexp(LY, l_prev + log(S_prev - S))
                x += l_prev
                if a0 == ninf:
                    v = b + x
                elif x == ninf:
                    v = b + a0
                elif a0 >= x:
                    v = b + a0 + log1p(exp(x - a0))
                else:
                    v = b + x + log1p(exp(a0 - x))
            ly.append(v)
            x = l + sn  # e = logaddexp(LY, l + log S)
            if v == ninf:
                e = x
            elif x == ninf:
                e = v
            elif v >= x:
                e = v + log1p(exp(x - v))
            else:
                e = x + log1p(exp(v - x))
            w = e + lp
            vs.append(w)
            if w > best or i == 0:
                best, bi, ebest = w, i, e
        if len(vs) == 1:
            ev = vs[0]
        else:
            ev = best + log(sum([exp(w - best) for w in vs]))
        self.l = l
        self.ly = ly
        self.lsf = lsf
        self.tau = tau
        self.n += 1
        self.last_t = float(t)
        # a NaN weight: np.argmax's answer may differ from the loop's, dominant_evidence computes it
        self._dom = (ly, lsf, self._log_prior, l, bi, ebest) if ev == ev else None
        p = l + lsf[bi] - ebest
        return ev, math.exp(p if p < 0.0 else 0.0)

    def update(self, t: float, y: int) -> None:
        """Apply one observation ``y`` (0/1) at time ``t`` (s)."""
        self.step(float(t), int(y))

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
        """JSON-serialisable state (:meth:`set_state` restores it)."""
        return {"origin": self.origin, "n": self.n, "l": self.l, "ly": encode_floats(self.ly), "tau": self.tau,
                "lsf": encode_floats(self.lsf), "last_t": self.last_t, "log_prior": encode_floats(self.log_prior)}

    def set_state(self, s: dict[str, Any]) -> None:
        """Restore a state from :meth:`get_state`."""
        self.origin = s["origin"]
        self.n = int(s["n"])
        self.l = float(s["l"])
        self.ly = decode_floats(s["ly"]).tolist()
        self.tau = float(s["tau"])
        self.lsf = decode_floats(s["lsf"]).tolist()
        self.last_t = s["last_t"]
        self.log_prior = decode_floats(s["log_prior"])
