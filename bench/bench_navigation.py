"""Navigation speed: shortest paths per start-goal pair, and the 250-query navigation task.

1. Per pair: the start -> true-receptacle pairs of 80 seeded queries on the synthetic lab's grid
   (the goal is the middle cell of the receptacle's approach set; the doors as at the query time;
   unreachable pairs included). Timed per pair, in the same run:
   - ``reference``: the pure-Python A* (``astar_reference``, the test oracle and the old ``astar``);
   - ``planner``: ``GridPlanner.path`` with the graph already built (``PlanningCache.shortest_path``,
     what the library uses for many pairs on one grid);
   - ``one-shot``: ``astar(free, start, goal, res)``, which builds what it needs on every call.
   Lengths are checked to agree (1e-9). Ratios are reference / new per pair, medians over pairs.
2. The navigation task: 250 queries x 5 methods (oracle, last-seen map, fremen,
   time_of_week_frequency, perpetua_star), predictive, on the same lab. With ``--baseline-ref REF``
   the same task of git revision REF (extracted with ``git archive`` into a temporary directory)
   runs in alternation with this tree, each in its own process, and the ratio is reported.

Every measurement is repeated ``--repeat`` times (default 3); medians are reported with the load
average (``os.getloadavg``). Times are CPU seconds of the measuring process (``time.process_time``:
on a shared machine other jobs' load then inflates them far less than wall time); the task also
reports wall seconds. Run:

    python bench/bench_navigation.py [--quick] [--repeat 3] [--baseline-ref main]

Writes bench/out/navigation.json.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
METHODS = ["oracle", "last_seen_map", "fremen", "time_of_week_frequency", "perpetua_star"]


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def task_once(n_queries: int, seed: int) -> dict:
    """One navigation task run of the tree on sys.path (the child process of ``--task-json``)."""
    from psg_data.navigation import NavigationEnv, run_navigation
    from psg_data.synth._model import LabModel

    t0 = time.perf_counter()
    env = NavigationEnv.from_lab(LabModel(seed=seed))
    t_env = time.perf_counter() - t0
    from psg_data.navigation import build_filters

    w0, t0 = time.perf_counter(), time.process_time()
    filters = {m: build_filters(env, m) for m in METHODS}  # fitting: estimator code, not navigation's
    t_fit = time.process_time() - t0
    t0 = time.process_time()
    res = run_navigation(env, filters, seed=seed, n_queries=n_queries, setting="predictive")
    t_nav = time.process_time() - t0
    return {"env_s": t_env, "fit_s": t_fit, "episodes_s": t_nav, "run_s": t_fit + t_nav,
            "wall_s": time.perf_counter() - w0,
            "per_method_s": res.timings_s,
            "overall_sr": {r["method"]: r["overall_sr_mean"] for r in res.summary.to_dict("records")}}


def pairs_bench(n_pairs: int, seed: int, repeat: int) -> dict:
    from psg_data.navigation import NavigationEnv, PlanningCache, astar, astar_reference, make_queries
    from psg_data.synth._model import LabModel

    env = NavigationEnv.from_lab(LabModel(seed=seed))
    cache = PlanningCache(env.grid)
    res_m = env.grid.resolution_m
    pairs = []
    for q in make_queries(env, n_pairs, seed=seed + 1):
        if q.gt_receptacle is None:
            continue
        cfg = cache.key(q.doors_open)
        goal_cells = np.argwhere(cache.approach(q.gt_receptacle, cfg))
        if len(goal_cells):
            pairs.append((cfg, q.start_cell, tuple(int(v) for v in goal_cells[len(goal_cells) // 2]), q.gt_receptacle))
    for cfg in {p[0] for p in pairs}:  # build the graphs and components once (the planner's warm state)
        _ = cache.planner(cfg).components
    ref = np.zeros((repeat, len(pairs)))
    warm = np.zeros_like(ref)
    cold = np.zeros_like(ref)
    reachable = np.zeros(len(pairs), bool)
    for r in range(repeat):
        for k, (cfg, s, g, _) in enumerate(pairs):
            free = env.grid.free(cfg)
            t0 = time.process_time()
            a = astar_reference(free, s, g, res_m)
            t1 = time.process_time()
            b = cache.shortest_path(s, g, cfg)
            t2 = time.process_time()
            c = astar(free, s, g, res_m)
            t3 = time.process_time()
            ref[r, k], warm[r, k], cold[r, k] = t1 - t0, t2 - t1, t3 - t2
            for x in (b, c):
                if math.isfinite(a.length_m) != math.isfinite(x.length_m) or (
                        math.isfinite(a.length_m) and abs(a.length_m - x.length_m) > 1e-9):
                    raise SystemExit(f"length mismatch on pair {k}: {a.length_m} vs {x.length_m}")
            reachable[k] = a.found
    out = {"pairs": len(pairs), "n_reachable": int(reachable.sum()), "grid": list(env.grid.shape),
           "resolution_m": res_m, "load": _load()}
    for name, sel in (("all", slice(None)), ("reachable", reachable), ("unreachable", ~reachable)):
        if not np.any(np.ones(len(pairs), bool)[sel]):
            continue
        med = lambda a: float(np.median(np.median(a[:, sel], axis=1)))  # noqa: E731  median over repeats of medians
        out[name] = {"reference_ms": 1e3 * med(ref), "planner_ms": 1e3 * med(warm), "one_shot_ms": 1e3 * med(cold),
                     "ratio_planner": float(np.median([np.median(ref[r, sel] / warm[r, sel]) for r in range(repeat)])),
                     "ratio_one_shot": float(np.median([np.median(ref[r, sel] / cold[r, sel]) for r in range(repeat)])),
                     "total_ratio_planner": float(ref[:, sel].sum() / warm[:, sel].sum()),
                     "total_ratio_one_shot": float(ref[:, sel].sum() / cold[:, sel].sum())}
    # the pair of the former benchmark: the first present-target query of seed + 1
    k0 = 0
    out["first_pair"] = {"reference_ms": 1e3 * float(np.median(ref[:, k0])),
                         "planner_ms": 1e3 * float(np.median(warm[:, k0])),
                         "one_shot_ms": 1e3 * float(np.median(cold[:, k0]))}
    t0 = time.process_time()
    cache.field(pairs[0][3], pairs[0][0])
    out["one_field_ms"] = 1e3 * (time.process_time() - t0)
    return out


def _child(src: Path, n_queries: int, seed: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    code = (f"import json, sys; sys.path.insert(0, {str(ROOT / 'bench')!r}); import bench_navigation as b; "
            f"print(json.dumps(b.task_once({n_queries}, {seed})))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=str(src))
    if out.returncode != 0:
        raise SystemExit(f"navigation task of {src} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def task_bench(n_queries: int, seed: int, repeat: int, baseline_ref: str | None) -> dict:
    runs: dict[str, list[dict]] = {"this": [], "baseline": []}
    with tempfile.TemporaryDirectory(prefix="psg-nav-bench-") as tmp:
        base = None
        if baseline_ref:
            base = Path(tmp) / "baseline"
            base.mkdir()
            arc = subprocess.run(["git", "-C", str(ROOT), "archive", baseline_ref], capture_output=True, check=True)
            subprocess.run(["tar", "-x", "-C", str(base)], input=arc.stdout, check=True)
        for _ in range(repeat):
            runs["this"].append(_child(ROOT, n_queries, seed))
            if base is not None:
                runs["baseline"].append(_child(base, n_queries, seed))
    out: dict = {"n_queries": n_queries, "methods": METHODS, "load": _load(),
                 **{f"this_{k}": [r[k] for r in runs["this"]] for k in ("run_s", "fit_s", "episodes_s", "wall_s")},
                 "this_per_method_s": runs["this"][-1]["per_method_s"]}
    if runs["baseline"]:
        out["baseline_ref"] = baseline_ref
        for k in ("run_s", "fit_s", "episodes_s", "wall_s"):
            out[f"baseline_{k}"] = [r[k] for r in runs["baseline"]]
            out[f"ratio_{k}"] = float(np.median([b[k] / a[k] for a, b in zip(runs["this"], runs["baseline"])]))
        out["ratio"] = out["ratio_run_s"]
        out["same_results"] = runs["this"][-1]["overall_sr"] == runs["baseline"][-1]["overall_sr"]
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="30 pairs, 50 queries, one repeat")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0, help="lab seed and query seed")
    ap.add_argument("--baseline-ref", default=None, help="git revision whose navigation task runs alongside")
    args = ap.parse_args()
    repeat = 1 if args.quick else max(1, args.repeat)
    n_pairs, n_queries = (30, 50) if args.quick else (80, 250)
    print(f"machine: {platform.node()} ({platform.machine()}, {os.cpu_count()} CPUs, Python "
          f"{platform.python_version()}); load average at start {_load()}")
    pb = pairs_bench(n_pairs, args.seed, repeat)
    print(f"shortest paths, {pb['pairs']} start-goal pairs ({pb['n_reachable']} reachable) on a {pb['grid'][0]} x "
          f"{pb['grid'][1]} grid at {pb['resolution_m']} m, {repeat} repeat(s); load {pb['load']}")
    for name in ("all", "reachable", "unreachable"):
        if name in pb:
            d = pb[name]
            print(f"  {name:12s} median per pair: reference A* {d['reference_ms']:7.2f} ms | planner "
                  f"{d['planner_ms']:6.3f} ms (x{d['ratio_planner']:.1f}; total x{d['total_ratio_planner']:.1f}) | "
                  f"one-shot astar() {d['one_shot_ms']:6.2f} ms (x{d['ratio_one_shot']:.1f}; total "
                  f"x{d['total_ratio_one_shot']:.1f})")
    fp = pb["first_pair"]
    print(f"  former benchmark pair: reference {fp['reference_ms']:.1f} ms, planner {fp['planner_ms']:.2f} ms, "
          f"one-shot {fp['one_shot_ms']:.2f} ms; one multi-source Dijkstra field {pb['one_field_ms']:.1f} ms")
    tb = task_bench(n_queries, args.seed, repeat, args.baseline_ref)
    print(f"navigation task, {n_queries} queries x {len(METHODS)} methods (predictive), {repeat} run(s); load "
          f"{tb['load']}")
    for k, what in (("run_s", "whole task, CPU"), ("fit_s", "fitting, CPU"), ("episodes_s", "navigation, CPU"),
                    ("wall_s", "whole task, wall")):
        line = f"  {what:24s} this: median {float(np.median(tb['this_' + k])):6.2f} s {['%.2f' % x for x in tb['this_' + k]]}"
        if "ratio" in tb:
            line += (f" | {tb['baseline_ref']}: {float(np.median(tb['baseline_' + k])):6.2f} s "
                     f"{['%.2f' % x for x in tb['baseline_' + k]]} | baseline / this x{tb['ratio_' + k]:.2f}")
        print(line)
    if "ratio" in tb:
        print(f"  (same run, alternating processes); same overall SR as the baseline: {tb['same_results']}")
    out = ROOT / "bench" / "out"
    out.mkdir(exist_ok=True)
    (out / "navigation.json").write_text(json.dumps({"pairs": pb, "task": tb, "repeat": repeat}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
