"""Estimator cost benchmark: update / predict cost per observation, FreMEn fit, memory per edge.

Run: python bench/bench_estimators.py [--quick]

Everything is measured in the same run, side by side with a straightforward per-observation
Python loop of the same equations (persistence + emergence mixtures with K log-normal components,
discounted evidence, model selection), so the ratios are machine independent. Reference figures
from the issue (same kind of machine): Perpetua reference (JAX) ~95 us per update; Rosen's C++
persistence filter 1e6 updates in 0.14 s (exponential prior); public C++ FreMEn fit at N = 1e6,
K = 1000 in 17.8 s; the paper's memory per edge 28 KB (5 components, 1000 FreMEn coefficients).
"""

from __future__ import annotations

import argparse
import json
import math
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from psg_data.estimators import FremenModel, SurvivalMixture, get_estimator  # noqa: E402
from psg_data.estimators._fremen import _direct_sums  # noqa: E402
from psg_data.estimators._perpetua_star import PerpetuaStarFilter  # noqa: E402
from psg_data.estimators._priors import ConstantPrior  # noqa: E402

T0 = 1_704_085_200.0
K = 5
PER = SurvivalMixture("lognormal", np.full(K, 1 / K), np.log(3600.0 * np.array([0.5, 1, 3, 8, 24])), np.full(K, 0.5))
EMG = SurvivalMixture("lognormal", np.full(K, 1 / K), np.log(3600.0 * np.array([0.3, 1, 2, 6, 12])), np.full(K, 0.7))


def stream(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = T0 + np.cumsum(rng.uniform(30, 90, n))
    x = (np.mod(t, 86400) < 43200).astype(np.int8)
    y = np.where(rng.random(n) < 0.1, 1 - x, x).astype(np.int8)
    return t, y


def timeit(fn, min_time: float = 0.2) -> float:
    """Seconds per call (best of repeated runs within ~min_time)."""
    best = math.inf
    start = time.perf_counter()
    reps = 0
    while reps < 3 or (time.perf_counter() - start < min_time and reps < 50):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        reps += 1
    return best


# ------------------------------------------------------------------ straightforward Python loops
def _lsf(mu: float, sd: float, tau: float) -> float:
    if tau <= 0:
        return 0.0
    z = (math.log(tau) - mu) / sd
    s = 0.5 * math.erfc(z / math.sqrt(2))
    return math.log(s) if s > 0 else -0.5 * z * z - math.log(z * math.sqrt(2 * math.pi))


def _lae(a: float, b: float) -> float:
    if a == -math.inf:
        return b
    if b == -math.inf:
        return a
    m = max(a, b)
    return m + math.log1p(math.exp(-abs(a - b)))


def python_loop_update(t: np.ndarray, y: np.ndarray, gamma: float = 0.99) -> float:
    """Per-observation loop: both mixtures (K components), evidences, discounted model likelihood."""
    pm = pf = 0.1
    models = []
    for surv, emergence in ((PER, False), (EMG, True)):
        la = (math.log(1 - pf), math.log(pf)) if emergence else (math.log(pm), math.log(1 - pm))
        lb = (math.log(pm), math.log(1 - pm)) if emergence else (math.log(1 - pf), math.log(pf))
        models.append({"surv": surv, "la": la, "lb": lb, "l": 0.0, "ly": [-math.inf] * K, "lsf": [0.0] * K,
                       "E": 0.0, "L": 0.0})
    t0 = float(t[0])
    for ti, yi in zip(t.tolist(), y.tolist()):
        for m in models:
            s = m["surv"]
            tau = ti - t0
            l_prev = m["l"]
            m["l"] = l_prev + m["la"][yi]
            tot = -math.inf
            for k in range(K):
                new = _lsf(s.p1[k], s.p2[k], tau)
                old = m["lsf"][k]
                d = new - old
                logdelta = old + (math.log(-math.expm1(d)) if d < 0 else -math.inf) if d < 0 else -math.inf
                m["ly"][k] = m["lb"][yi] + _lae(m["ly"][k], l_prev + logdelta)
                m["lsf"][k] = new
                tot = _lae(tot, math.log(s.weights[k]) + _lae(m["ly"][k], m["l"] + new))
            m["L"] = gamma * m["L"] + (tot - m["E"])
            m["E"] = tot
    return models[0]["L"] - models[1]["L"]


def python_loop_predict(times: np.ndarray, f: PerpetuaStarFilter) -> list[float]:
    """Per-query loop of eqs. 13-14 (dominant components fixed between observations)."""
    out = []
    kp, ke = f.per.dominant(), f.emg.dominant()
    ep, ee = float(f.per.component_log_evidence()[kp]), float(f.emg.component_log_evidence()[ke])
    for ti in times.tolist():
        pp = math.exp(min(f.per.l + _lsf(PER.p1[kp], PER.p2[kp], ti - f.per.origin) - ep, 0.0))
        pe = 1 - math.exp(min(f.emg.l + _lsf(EMG.p1[ke], EMG.p2[ke], ti - f.emg.origin) - ee, 0.0))
        a = math.exp(-f.alpha0_per_s * (ti - f._last_t))
        w = 1 / (1 + math.exp(-(a * (f.L[1] - f.L[0]))))
        out.append(w * pe + (1 - w) * pp)
    return out


def star_filter() -> PerpetuaStarFilter:
    return PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, ConstantPrior(0.5), gamma=0.99,
                              alpha0_per_s=0.01 / 60, prior_floor=1e-3)


def fmt(s: float) -> str:
    return f"{s * 1e6:9.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N up to 1e5 and shorter runs")
    args = ap.parse_args()
    sizes = [10**3, 10**4, 10**5] if args.quick else [10**3, 10**4, 10**5, 10**6]
    print("# Update cost per observation (us/obs); ratio = Python loop / this")
    print(f"{'N':>8} {'loop':>9} | {'p*_batch':>9} {'ratio':>7} | {'p*_one':>9} {'ratio':>7} | "
          f"{'pf_batch':>9} | {'perpetua':>9} | restarts")
    for n in sizes:
        t, y = stream(n)
        nl = min(n, 20_000)
        loop = timeit(lambda: python_loop_update(t[:nl], y[:nl]), 0.0) / nl

        def batch():
            f = star_filter()
            f.update_many(t, y)
            batch.f = f  # type: ignore[attr-defined]

        tb = timeit(batch, 0.5 if n < 10**6 else 0.0) / n
        restarts = batch.f.n_restarts  # type: ignore[attr-defined]
        n1 = min(n, 3000)

        def one():
            f = star_filter()
            for ti, yi in zip(t[:n1].tolist(), y[:n1].tolist()):
                f.update(ti, yi)

        t1 = timeit(one, 0.0) / n1
        pf = get_estimator("persistence_filter", survival="exponential", survival_params=(1 / 3600.0, 1.0),
                           p_m=0.1, p_f=0.1).fit([])
        tpf = timeit(lambda: pf.make_filter(("o", "r")).update_many(t, y), 0.0) / n
        np_ = min(n, 2000)
        perp = get_estimator("perpetua", p_m=0.1, p_f=0.1).fit([])
        perp.survivals_[("o", "r")] = (PER, EMG)
        tpe = timeit(lambda: perp.make_filter(("o", "r")).update_many(t[:np_], y[:np_]), 0.0) / np_
        print(f"{n:>8} {fmt(loop)} | {fmt(tb)} {loop / tb:7.1f} | {fmt(t1)} {loop / t1:7.1f} | {fmt(tpf)} | "
              f"{fmt(tpe)} | {restarts}")

    print("\n# Predict cost per query time (us/query), perpetua_star after 1e4 updates")
    t, y = stream(10_000)
    f = star_filter()
    f.update_many(t, y)
    print(f"{'Q':>8} {'loop':>9} | {'p*':>9} {'ratio':>7} | {'perpetua':>9}")
    perp_f = perp.make_filter(("o", "r"))
    perp_f.update_many(t[:2000], y[:2000])
    for q in ([10**3, 10**4, 10**5] if args.quick else [10**3, 10**4, 10**5, 10**6]):
        times = t[-1] + np.linspace(0, 7 * 86400, q)
        ql = min(q, 20_000)
        loop = timeit(lambda: python_loop_predict(times[:ql], f), 0.0) / ql
        tp = timeit(lambda: f.predict(times), 0.2) / q
        tpp = timeit(lambda: perp_f.predict(times + (t[1999] - t[-1])), 0.0) / q
        print(f"{q:>8} {fmt(loop)} | {fmt(tp)} {loop / tp:7.1f} | {fmt(tpp)}")

    print("\n# FreMEn fit (s): harmonic FFT vs chunked direct numpy sums, K = 1000")
    rng = np.random.default_rng(0)
    for n in sizes:
        tau = np.sort(rng.uniform(0, 6 * 604800.0, n))
        yy = (rng.random(n) < 0.5).astype(float)
        tf = timeit(lambda: FremenModel(1000).add(tau, yy, method="fft"), 0.0)
        nd = min(n, 10**5)
        td = timeit(lambda: (_direct_sums(tau[:nd], yy[:nd], 1000, 604800.0),
                             _direct_sums(tau[:nd], np.ones(nd), 1000, 604800.0)), 0.0) * n / nd
        print(f"N={n:>8}: fft {tf:7.3f} s   direct {td:8.3f} s{' (extrapolated)' if nd < n else ''}   "
              f"ratio {td / tf:6.1f}")

    print("\n# Memory per edge (perpetua_star, 5 + 5 components, FreMEn prior with 1000 candidate periods)")
    from psg_data.synth.persistence_benchmark import make_persistence_benchmark

    b = make_persistence_benchmark(seed=0)
    est = get_estimator("perpetua_star", n_periods=1000).fit(b.train_streams, val_streams=b.val_streams,
                                                         timezone=b.timezone)
    sizes_json, sizes_pickle = [], []
    for s in b.train_streams:
        g = est.make_filter(s.edge)
        g.update_many(s.t_s, s.y)
        st = g.get_state()
        sizes_json.append(len(json.dumps(st)))
        sizes_pickle.append(len(pickle.dumps(g)))
    order = [info["order"] for info in est.fit_info_.values()]
    print(f"state JSON: mean {np.mean(sizes_json) / 1024:.2f} KB, max {max(sizes_json) / 1024:.2f} KB; "
          f"pickled filter: mean {np.mean(sizes_pickle) / 1024:.2f} KB, max {max(sizes_pickle) / 1024:.2f} KB; "
          f"FreMEn orders chosen {order}")
    full = FremenModel(1000).add(np.arange(10.0), np.ones(10))
    print(f"(keeping all 1000 FreMEn coefficients instead: +{len(json.dumps(full.to_dict())) / 1024:.1f} KB JSON, "
          f"{(full.s.nbytes + full.z.nbytes) / 1024:.1f} KB as arrays)")


if __name__ == "__main__":
    main()
