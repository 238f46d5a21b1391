"""Figure: Perpetua*'s eq. 14 far from the last observation, on the built-in lab (predictive setting).

Run: python docs/figures/long_horizon.py [OUT.png]   (default docs/figures/perpetua_star_long_horizon.png)
     python docs/figures/long_horizon.py --out DIR  (DIR/perpetua_star_long_horizon.png and DIR/results.json,
                                                     the averages RESULTS.md 6.2 renders; DIR must not exist)

Fits ``perpetua_star`` (FreMEn prior, cadence defaults) on the lab's training weeks, feeds each
edge its training observations and predicts the test week without further observations. For one
moving object it plots, per receptacle, the switching prior f(t), eq. 14's belief and the
``perpetua_star_annealed`` variant against the true state; it prints, over all moving edges and
all test times more than 24 h after the last observation, the mean of each for edges last seen
absent and last seen present.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # docs/: the shared results_out helper
from results_out import refuse, write  # noqa: E402


def main(out: Path) -> dict[str, dict[str, float]]:
    """Draw the figure into ``out``; return the printed averages per last-seen state."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    from psg_data.cli._eval_inputs import persistence_tasks, resolve_dataset
    from psg_data.estimators import get_estimator

    task = persistence_tasks(resolve_dataset(None, quiet=True), labels="gt", seeds=[0], quiet=True)[0][0]
    star = get_estimator("perpetua_star").fit(task.train_streams, timezone=task.timezone)
    ann = get_estimator("perpetua_star_annealed").fit(task.train_streams, timezone=task.timezone)
    rows = {"absent": [], "present": []}
    curves = {}
    for s in task.train_streams:
        gt_t, gt_y = task.ground_truth[s.edge]
        if s.y.min() == s.y.max():
            continue  # not a moving edge
        f, g = star.make_filter(s.edge), ann.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        g.update_many(s.t_s, s.y)
        b, a, prior = f.predict(gt_t), g.predict(gt_t), np.clip(star.priors_[s.edge](gt_t), 0, 1)
        curves[s.edge] = (gt_t, gt_y, prior, b, a, int(s.y[-1]))
        far = gt_t - s.t_s[-1] > 86400.0
        rows["present" if s.y[-1] == 1 else "absent"].append((prior[far], b[far], a[far], gt_y[far]))
    averages = {}
    for k, v in rows.items():
        p, b, a, y = (np.concatenate([r[i] for r in v]) for i in range(4))
        print(f"last seen {k:7s} ({len(v):2d} edges, > 24 h ahead): prior f {p.mean():.3f}  eq. 14 {b.mean():.3f}  "
              f"annealed {a.mean():.3f}  true occupancy {y.mean():.3f}")
        averages[k] = {"edges": len(v), "prior": float(p.mean()), "perpetua_star": float(b.mean()),
                       "perpetua_star_annealed": float(a.mean()), "true_occupancy": float(y.mean())}
    objs = sorted({e[0] for e in curves})  # sorted: the choice must not depend on the hash seed
    obj = max(objs, key=lambda o: sum(1 for e in curves if e[0] == o))
    edges = sorted(e for e in curves if e[0] == obj)
    fig, axes = plt.subplots(len(edges), 1, figsize=(10, 1.9 * len(edges) + 0.6), sharex=True)
    for ax, e in zip(np.atleast_1d(axes), edges):
        t, y, p, b, a, last = curves[e]
        h = (t - t[0]) / 3600.0
        ax.fill_between(h, 0, y, step="post", color="0.85", label="true state (present = 1)")
        ax.plot(h, p, color="tab:green", lw=1.2, label="switching prior f(t) (FreMEn)")
        ax.plot(h, b, color="tab:red", lw=1.5, label="perpetua_star (eq. 14)")
        ax.plot(h, a, color="tab:blue", lw=1.2, ls="--", label="perpetua_star_annealed (variant)")
        ax.set_ylim(-0.03, 1.03)
        ax.set_ylabel("P(present)")
        ax.set_title(f"{e[1]} (last seen {'present' if last else 'absent'} at the end of training)", fontsize=9)
    np.atleast_1d(axes)[-1].set_xlabel("hours into the test week (no observations: predictive setting; "
                                       "only scan hours 9:00-17:00 are scored, gaps are nights)")
    np.atleast_1d(axes)[0].legend(loc="upper right", fontsize=7, ncol=2)
    fig.suptitle(f"Perpetua* far from the last observation: {obj} on the built-in lab", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    return averages


def cli(argv: list[str] | None = None) -> int:
    """``[OUT.png]`` or ``--out DIR`` (figure and results.json, written into a folder renamed into place)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("png", nargs="?", type=Path, default=Path(__file__).with_name("perpetua_star_long_horizon.png"))
    ap.add_argument("--out", type=Path, help="write DIR/perpetua_star_long_horizon.png and DIR/results.json")
    a = ap.parse_args(argv)
    if a.out is None:
        main(a.png)
        return 0
    if (problem := refuse(a.out)) is not None:
        print(problem, file=sys.stderr)
        return 1
    write(a.out, lambda stage: {"far_from_last_observation": main(stage / "perpetua_star_long_horizon.png")})
    return 0


if __name__ == "__main__":
    sys.exit(cli())
