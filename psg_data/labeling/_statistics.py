"""What the privileged labels of a lab dataset see (RESULTS.md, section "The built-in lab").

Moving objects are those whose receptacle changes over the dataset's scans; a visit is a maximal
run of consecutive scans with a moving object on one receptacle.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from psg_data.errors import LabelingError

__all__ = ["visibility_statistics"]


def visibility_statistics(dataset: Any) -> dict[str, Any]:
    """Share of the visits of moving objects with at least one privileged code 1 (seen there), and
    share of the scans in which a present moving object is seen.

    Args:
        dataset: a dataset or its path; it needs its ``schedule`` table (the ground truth).

    Raises:
        LabelingError: the dataset has no schedule table.
    """
    from psg_data.labeling._pipeline import compute_labels
    from psg_data.loaders import open_dataset

    ds = dataset if hasattr(dataset, "table") else open_dataset(dataset)
    res = compute_labels(ds, "privileged")
    if res.gt is None:
        raise LabelingError(f"{ds.root}: no schedule table; visibility statistics need the ground truth")
    present = res.gt.codes == 1  # (S, O, R)
    seen = res.labels.codes == 1
    on = present.any(axis=2)
    rec = np.where(on, present.argmax(axis=2), -1)  # (S, O) receptacle of each object, -1 absent
    moving = np.flatnonzero([len({tuple(np.flatnonzero(present[s, o])) for s in range(present.shape[0])}) > 1
                             for o in range(present.shape[1])])
    scans = np.arange(rec.shape[0])
    visits = n_seen = 0
    for o in moving:
        r = rec[:, o]
        starts = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
        seen_here = seen[scans, o, np.maximum(r, 0)] & (r >= 0)  # seen on the receptacle it is on
        kept = r[starts] >= 0
        visits += int(kept.sum())
        n_seen += int(np.logical_or.reduceat(seen_here, starts)[kept].sum())
    return {"visits_scanned": visits, "visits_seen_privileged": n_seen / max(visits, 1),
            "present_scans_seen_privileged": float(seen[:, moving].any(axis=2)[on[:, moving]].mean())}
