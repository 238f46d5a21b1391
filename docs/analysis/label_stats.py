"""What a dataset's label sources are, as numbers: the statistics ``psg-data label`` prints, in a results.json.

    python docs/analysis/label_stats.py /tmp/conv --source privileged --source observed \
        --source detections:/tmp/conv_detections.parquet --out /tmp/label_stats

Each source is computed again from the dataset by the labelling code (``compute_labels`` and
``summarize``, what ``psg-data label`` runs), reading the dataset's stored visibility table; nothing is
written into the dataset, so runs that read the same dataset can run beside this one. Per source:
edges, observations per edge, code counts, P_M / P_F against the schedule with their 95 % Wilson
intervals, (scan, receptacle) pairs visible, (scan, door) pairs observed and agreeing with the door
states, the perception path's matches; for a detections table, its detections per scan by kind.
RESULTS.md section 5 renders its label statistics from this file (results/manifest.json: ``ros2-labels``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # docs/: the shared results_out helper
from results_out import refuse, write  # noqa: E402


def source_stats(dataset: Any, source: str) -> dict[str, Any]:
    """The numbers of one label source of ``dataset`` (module docstring)."""
    from psg_data.labeling import compute_labels, parse_source, summarize

    res = compute_labels(dataset, parse_source(source), seed=0, reuse_visibility=True)
    s = summarize(res)
    out: dict[str, Any] = {"source": s.source, "edge_kind": s.edge_kind, "edges": s.n_edges,
                           "observations_per_edge": dict(zip(("mean", "min", "max"), s.obs_per_edge)),
                           "codes": {str(k): int(v) for k, v in sorted(s.codes.items())}}
    if s.rates is not None:
        r = s.rates
        out["error_rates"] = {"p_m": r.p_m, "p_m_ci": list(r.p_m_ci), "n_present": r.n_present, "p_f": r.p_f,
                              "p_f_ci": list(r.p_f_ci), "n_absent": r.n_absent, "confidence": r.confidence}
    if res.visibility is not None:
        d = res.visibility.to_pydict()
        vis = [bool(v) for k, v in zip(d["kind"], d["visible"]) if k == "receptacle"]
        scans = len(set(sid for k, sid in zip(d["kind"], d["scan_id"]) if k == "receptacle"))
        out["receptacles_visible"] = {"visible": sum(vis), "pairs": len(vis), "scans": scans,
                                      "per_scan": sum(vis) / scans if scans else float("nan"),
                                      "receptacles": len(vis) // scans if scans else 0}
    if res.doors is not None:
        out["doors"] = _door_stats(res)
    if res.perception is not None:
        p = res.perception
        out["perception"] = {"matches": int(p.matched.sum()), "mean_iou": float(p.mean_iou),
                             "unmatched_nodes": p.n_unmatched_nodes, "unassociated": p.n_unassociated,
                             "unknown_labels": p.n_unknown_labels}
    if source.startswith("detections:") and source.endswith(".parquet"):
        out["detections_file"] = _detection_counts(Path(source.split(":", 1)[1]))
    return out


def _door_stats(res: Any) -> dict[str, Any]:
    """(scan, door) pairs observed, and how many of those with a door-state truth agree with it."""
    dg = res.doors
    obs = dg.codes[:, :, 0] >= 0
    out: dict[str, Any] = {"observed": int(obs.sum()), "pairs": int(obs.size), "door_state_edges": int(dg.valid.sum())}
    if res.door_gt is not None and dg.source != "gt":
        ref = res.door_gt.aligned(dg)[:, :, 0]
        both = obs & (ref >= 0)
        out.update(agree=int((dg.codes[:, :, 0] == ref)[both].sum()), compared=int(both.sum()))
    return out


def _detection_counts(path: Path) -> dict[str, Any]:
    """Detections per scan by kind; object detections with a ground-truth id (``gt_id``) counted apart."""
    import pyarrow.parquet as pq

    t = pq.ParquetFile(path).read().to_pydict()
    scans = len(set(t["scan_id"]))
    kinds = t["kind"]
    gt = t.get("gt_id", [None] * len(kinds))
    true_objects = sum(1 for k, g in zip(kinds, gt) if k == "object" and g not in (None, ""))
    return {"scans": scans, "objects_per_scan": kinds.count("object") / scans,
            "true_objects_per_scan": true_objects / scans, "receptacles_per_scan": kinds.count("receptacle") / scans}


def main(argv: list[str] | None = None) -> int:
    """Command line: DATASET, --source (repeatable), --out DIR (a new folder: results.json)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--source", action="append", required=True, help="a label source (repeatable)")
    ap.add_argument("--out", type=Path, required=True, help="write DIR/results.json (DIR must not exist)")
    a = ap.parse_args(argv)
    from psg_data.errors import PsgDataError
    from psg_data.loaders import open_dataset
    if (problem := refuse(a.out)) is not None:
        print(problem, file=sys.stderr)
        return 1
    try:
        ds = open_dataset(a.dataset)
        doc = {"dataset": str(a.dataset), "sources": {src.split(":", 1)[0]: source_stats(ds, src) for src in a.source}}
    except PsgDataError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    write(a.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
