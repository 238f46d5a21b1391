"""What Perpetua*'s training decides on the demo lab, per label source (RESULTS.md 6.1).

Run: python docs/analysis/training_decisions.py [--out DIR]   (four fits; prints JSON, or writes
DIR/results.json, the form results/build.py renders from)

For each label source (`gt`, `noisy:0.1`, `noisy:0.2`, `privileged`) it fits `perpetua_star` with its
defaults on the demo lab's training streams and records the estimator's ``fit_summary_``: the error
rates the pooled HMM estimated, the settings derived from the training cadence (forgetting half-life,
alpha0, FreMEn periods; each with where it came from), the HMM's fitted stay probabilities, and how
many objects the training saw.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

LABELS = ("gt", "noisy:0.1", "noisy:0.2", "privileged")


def plain(x: Any) -> Any:
    """``x`` with numpy scalars/arrays and tuple keys made JSON-safe (lists, floats, strings)."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def fit_summaries() -> list[dict[str, Any]]:
    """``[{"labels": source, **fit_summary_, "train_objects": n}]``: one default ``perpetua_star`` fit per label
    source on the demo lab.
    """
    import psg_data
    from psg_data.estimators import get_estimator
    from psg_data.evaluation import persistence_task_from_dataset

    out: list[dict[str, Any]] = []
    for labels in LABELS:
        task = persistence_task_from_dataset(psg_data.datasets.demo(), labels=labels)
        est = get_estimator("perpetua_star").fit(task.train_streams, timezone=task.timezone)
        objects = len({s.edge[0] for s in task.train_streams if len(s)})
        out.append({"labels": labels, **plain(est.fit_summary_), "train_objects": objects})  # type: ignore[attr-defined]
    return out


def main(argv: list[str] | None = None) -> int:
    """Print the fits' summaries as JSON, or write them to ``--out DIR/results.json``; 1 if DIR exists."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write DIR/results.json (DIR must not exist) instead of printing")
    a = ap.parse_args(argv)
    text = json.dumps({"fits": fit_summaries()}, indent=1, default=str) + "\n"
    if a.out is None:
        sys.stdout.write(text)
        return 0
    if a.out.exists():
        print(f"error: {a.out}: output exists; expected a new folder", file=sys.stderr)
        return 1
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{a.out.name}.", dir=a.out.parent))
    (tmp / "results.json").write_text(text, encoding="utf-8")
    os.replace(tmp, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
