"""Where Perpetua* loses to FreMEn with the 2 h horizon: scores split by the filter's last observation.

Run: python docs/analysis/last_state_split.py [--out DIR]   (about 15 s on a warm cache; prints a table;
with --out also writes DIR/results.json, the form results/build.py renders RESULTS.md 6.1 from)

Evaluates the main job's protocol on the demo lab (adaptive, default horizon and weighting, labels
gt, estimator seed 0), keeps every edge's beliefs, and splits the scored time by the state of the
last observation each filter had at that time (the last training or test observation at least one
horizon before it). Per estimator and split it prints the scored hours, the true occupancy, the
mean belief and the time-weighted rates at threshold 0.5, pooled over all edges: TPR (present time
predicted present), TNR (absent time predicted absent) and their mean. The pooled rates are a
diagnostic, not the table's B-Acc, which is computed per edge and then averaged by scored time.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # docs/: the shared results_out helper
from results_out import refuse, write  # noqa: E402

NAMES = ("perpetua_star", "perpetua_star_annealed", "fremen", "time_of_week_frequency", "last_seen")


def last_state(t: np.ndarray, hist: tuple[np.ndarray, np.ndarray], obs_t: np.ndarray, obs_y: np.ndarray,
               horizon_s: float) -> np.ndarray:
    """State (0/1) of the last observation the filter had at each time ``t``; -1 before the first."""
    all_y = np.concatenate([hist[1], obs_y]).astype(np.int64)
    idx = hist[0].size + np.searchsorted(obs_t, t - horizon_s, side="right") - 1
    if all_y.size == 0:
        return np.full(t.shape, -1, np.int64)
    return np.where(idx >= 0, all_y[np.clip(idx, 0, None)], -1)


def main(argv: list[str] | None = None) -> int:
    """Print the split table (and write ``--out DIR/results.json``); 0 on success, 1 if DIR exists."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="also write DIR/results.json (DIR must not exist)")
    a = ap.parse_args(argv)
    if (problem := refuse(a.out)) is not None:
        print(problem, file=sys.stderr)
        return 1
    import psg_data
    from psg_data.evaluation import PersistenceOptions, persistence_task_from_dataset, run_persistence_task

    task = persistence_task_from_dataset(psg_data.datasets.demo(), labels="gt")
    res = run_persistence_task(list(NAMES), task, PersistenceOptions(seeds=(0,)),
                               keep_predictions=[s.edge for s in task.test_streams])
    horizon = float(res.config["horizon"])
    hist = {tuple(map(str, s.edge)): (np.asarray(s.t_s), np.asarray(s.y)) for s in task.train_streams}
    sums: dict[tuple[str, int], np.ndarray] = {}
    for tr in res.traces:
        h = hist.get(tuple(map(str, tr.edge)), (np.zeros(0), np.zeros(0, np.int8)))
        last = last_state(np.asarray(tr.t_s), h, np.asarray(tr.obs_t_s), np.asarray(tr.obs_y), horizon)
        y, p, w = np.asarray(tr.truth), np.asarray(tr.belief), np.asarray(tr.weight)
        for state in (0, 1):
            m = ((y == 0) | (y == 1)) & (last == state)
            pos, pred = y[m] == 1, p[m] >= 0.5
            s = sums.setdefault((tr.estimator, state), np.zeros(5))
            s += [np.sum(w[m] * (pos & pred)), np.sum(w[m] * pos), np.sum(w[m] * (~pos & ~pred)),
                  np.sum(w[m] * p[m]), np.sum(w[m])]
    print(f"horizon {horizon:.0f} s; table B-Acc: "
          + ", ".join(f"{n} {res.summary[n]['balanced_accuracy'].mean:.3f}" for n in NAMES))
    print(f"{'estimator':24s} {'last seen':9s} {'hours':>6s} {'occupancy':>9s} {'mean p':>7s} {'TPR':>6s} "
          f"{'TNR':>6s} {'mean':>6s}")
    rows = []
    for n in NAMES:
        for state in (1, 0):
            tp, pos, tn, sp, sw = sums[(n, state)]
            tpr, tnr = tp / pos, tn / (sw - pos)
            print(f"{n:24s} {'present' if state else 'absent':9s} {sw / 3600:6.0f} {pos / sw:9.3f} {sp / sw:7.3f} "
                  f"{tpr:6.3f} {tnr:6.3f} {(tpr + tnr) / 2:6.3f}")
            rows.append({"method": n, "last_seen": "present" if state else "absent", "hours": float(sw / 3600),
                         "occupancy": float(pos / sw), "mean_belief": float(sp / sw), "tpr": float(tpr),
                         "tnr": float(tnr), "mean_rate": float((tpr + tnr) / 2)})
    if a.out is not None:
        table_bacc = {n: float(res.summary[n]["balanced_accuracy"].mean) for n in NAMES}
        write(a.out, {"horizon_s": horizon, "balanced_accuracy": table_bacc, "rows": rows})
    return 0






if __name__ == "__main__":
    sys.exit(main())
