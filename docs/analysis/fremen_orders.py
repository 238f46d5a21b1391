"""FreMEn's chosen orders under its order and duration rules (RESULTS.md 3.6), written as JSON.

Run: python docs/analysis/fremen_orders.py --out DIR   (writes DIR/results.json; about 10 s warm)

Fits ``fremen`` with each pair of rules (``order_rule`` reference | mae, ``duration_rule`` on | off)
exactly as psg-eval builds it (the task's hints added, e.g. the benchmark's 1000 periods), on the
training streams of two tasks, and records ``fit_summary_["order_selection"]``'s order per edge:

* ``lab``: the demo lab (or ``--dataset PATH``), labels gt; Perpetua*'s FreMEn prior is fitted by the
  same function on the same streams, so its orders are these.
* ``benchmark``: draw 0 of the Sec. V-A benchmark (``--train-weeks``: its training weeks, default 4,
  the benchmark's), the order chosen on its validation week.

Per task and rule pair (keys ``reference_on``, ``reference_off``, ``mae_on``, ``mae_off``): ``orders``
(edge -> order, in the fit's edge order), ``listed`` (the orders comma-separated, in that order),
``median``, ``at_zero`` (edges at order 0) and ``edges``. RESULTS.md renders its order columns from
this file through results/manifest.json's run ``fremen-orders``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # docs/: the shared results_out helper
from results_out import refuse, write  # noqa: E402

RULES = {"reference_on": "fremen", "reference_off": "fremen:order_rule=reference,duration_rule=off",
         "mae_on": "fremen:order_rule=mae,duration_rule=on", "mae_off": "fremen:order_rule=mae,duration_rule=off"}


def orders_of(task: Any, spec_text: str) -> dict[str, Any]:
    """The orders ``fremen`` with settings ``spec_text`` chooses on ``task``'s training streams."""
    from psg_data.cli._eval_inputs import parse_estimator_spec
    from psg_data.evaluation._persistence_job import factories_for

    spec = parse_estimator_spec(spec_text)
    est = factories_for([spec], task)[spec.label](random_state=0)
    est.fit(task.train_streams, val_streams=task.val_streams, timezone=task.timezone)
    sel = est.fit_summary_["order_selection"]
    orders = {edge: int(v["order"]) for edge, v in sel["edges"].items()}
    values = list(orders.values())
    return {"spec": spec_text, "order_rule": sel["order_rule"], "duration_rule": sel["duration_rule"],
            "orders": orders, "listed": ", ".join(map(str, values)), "median": float(np.median(values)),
            "at_zero": sum(v == 0 for v in values), "edges": len(values)}


def main(argv: list[str] | None = None) -> int:
    """Fit, then write ``--out``/results.json atomically; 0 on success."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="new folder to write results.json into")
    p.add_argument("--dataset", default=None, help="a lab dataset folder (default: the demo lab)")
    p.add_argument("--train-weeks", type=int, default=4, help="the benchmark's training weeks (default 4)")
    a = p.parse_args(argv)
    if (problem := refuse(a.out)) is not None:
        print(problem, file=sys.stderr)
        return 1
    import psg_data
    from psg_data.evaluation import persistence_task_from_dataset
    from psg_data.evaluation._dataset_task import persistence_task_from_benchmark

    lab = persistence_task_from_dataset(Path(a.dataset) if a.dataset else psg_data.datasets.demo(), labels="gt")
    bench = persistence_task_from_benchmark(0, train_weeks=a.train_weeks)
    doc = {"script": "docs/analysis/fremen_orders.py", "dataset": a.dataset or "demo",
           "lab": {k: orders_of(lab, s) for k, s in RULES.items()},
           "benchmark": {"draw": 0, "train_weeks": a.train_weeks,
                         **{k: orders_of(bench, s) for k, s in RULES.items()}}}
    write(a.out, doc)
    return 0






if __name__ == "__main__":
    raise SystemExit(main())
