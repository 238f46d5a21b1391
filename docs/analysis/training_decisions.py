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
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # docs/: the shared results_out helper
from results_out import refuse, write  # noqa: E402

LABELS = ("gt", "noisy:0.1", "noisy:0.2", "privileged")


def fit_summaries() -> list[dict[str, Any]]:
    """``[{"labels": source, **fit_summary_, "train_objects": n}]``: one default ``perpetua_star`` fit per label
    source on the demo lab.
    """
    import psg_data
    from psg_data.estimators import get_estimator
    from psg_data.evaluation import persistence_task_from_dataset
    from psg_data.evaluation._persistence_types import clean_json

    out: list[dict[str, Any]] = []
    for labels in LABELS:
        task = persistence_task_from_dataset(psg_data.datasets.demo(), labels=labels)
        est = get_estimator("perpetua_star").fit(task.train_streams, timezone=task.timezone)
        objects = len({s.edge[0] for s in task.train_streams if len(s)})
        out.append({"labels": labels, **clean_json(est.fit_summary_), "train_objects": objects})  # type: ignore[attr-defined]
    return out


def main(argv: list[str] | None = None) -> int:
    """Print the fits' summaries as JSON, or write them to ``--out DIR/results.json``; 1 if DIR exists."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write DIR/results.json (DIR must not exist) instead of printing")
    a = ap.parse_args(argv)
    if (problem := refuse(a.out)) is not None:
        print(problem, file=sys.stderr)
        return 1
    doc = {"fits": fit_summaries()}
    if a.out is None:
        sys.stdout.write(json.dumps(doc, indent=1, default=str) + "\n")
    else:
        write(a.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
