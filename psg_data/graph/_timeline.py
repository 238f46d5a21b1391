"""The scans of a dataset in time order: which form the map (training), and the truth between them."""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError

__all__ = ["DatasetTimeline", "WEEK_S"]

WEEK_S = 7 * 86400.0


@dataclass
class DatasetTimeline:
    """The scans of a dataset in time order with their ground truth (a step function between scans).

    Attributes:
        ids: scan ids, chronological.
        start_s, end_s: scan start / end times, float seconds UTC.
        map_ids: the map scans (chronological).
        by_scan: scan -> {object_id: receptacle_id | None} (the ``schedule`` table).
        door_by_scan: scan -> {door_id: is_open} (the ``door_states`` table; 'unknown' counts open).
        door_ids: the dataset's doors.
        t_map_s: end of the last map scan; t_end_s: end of the last later scan (or a week after).
    """

    ids: list[str]
    start_s: list[float]
    end_s: list[float]
    map_ids: list[str]
    by_scan: dict[str, dict[str, str | None]]
    door_by_scan: dict[str, dict[str, bool]]
    door_ids: list[str]
    t_map_s: float
    t_end_s: float

    @classmethod
    def from_dataset(cls, dataset: Any, map_scans: Sequence[str] | None = None, *, need_schedule: bool = True
                     ) -> DatasetTimeline:
        """Timeline of a dataset; map scans default to split 'train' (if no scan has a split, the
        first two thirds of the scans).

        Raises:
            EvaluationError: no scans, no map scans, or (``need_schedule``) an empty schedule.
        """
        scans = dataset.df("scans").sort_values(["start_stamp_ns", "scan_id"]).reset_index(drop=True)
        if scans.empty:
            raise EvaluationError(f"{dataset.root}: no scans; navigation needs scans with a schedule")
        sched = dataset.df("schedule") if dataset.has_table("schedule") else None
        if need_schedule and (sched is None or sched.empty):
            raise EvaluationError(f"{dataset.root}: table 'schedule' is empty; navigation needs ground truth")
        if map_scans is None:
            if scans["split"].notna().any():
                map_ids = scans.loc[scans["split"] == "train", "scan_id"].tolist()
            else:
                map_ids = scans["scan_id"].tolist()[: max(1, int(round(len(scans) * 2 / 3)))]
        else:
            map_ids = list(map_scans)
        if not map_ids:
            raise EvaluationError(f"{dataset.root}: no map scans (no scan with split 'train')")
        ids = scans["scan_id"].tolist()
        pos = {sid: k for k, sid in enumerate(ids)}
        unknown = [m for m in map_ids if m not in pos]
        if unknown:
            raise EvaluationError(f"{dataset.root}: map scans {unknown[:3]} are not in the scans table")
        by_scan: dict[str, dict[str, str | None]] = {sid: {} for sid in ids}
        if sched is not None:
            for sid, o, r in zip(sched["scan_id"], sched["object_id"], sched["receptacle_id"]):
                by_scan.setdefault(sid, {})[o] = None if r is None or (isinstance(r, float) and np.isnan(r)) else str(r)
        door_by_scan: dict[str, dict[str, bool]] = {}
        if dataset.has_table("door_states"):
            ds_ = dataset.df("door_states")
            for sid, d, st in zip(ds_["scan_id"], ds_["door_id"], ds_["state"]):
                door_by_scan.setdefault(sid, {})[d] = st != "closed"
        start_s = (scans["start_stamp_ns"].to_numpy(np.int64) / 1e9).tolist()
        end_s = (scans["end_stamp_ns"].to_numpy(np.int64) / 1e9).tolist()
        map_ids = sorted(map_ids, key=lambda x: pos[x])
        last = pos[map_ids[-1]]
        later = end_s[last + 1:]
        t_map = end_s[last]
        return cls(ids, start_s, end_s, map_ids, by_scan, door_by_scan,
                   list(dataset.doors) if dataset.has_table("doors") else [], float(t_map),
                   float(max(later) if later else t_map + WEEK_S))

    def scan_before(self, t_s: float) -> str:
        """The latest scan starting at or before ``t_s`` (the first scan before any)."""
        k = bisect.bisect_right(self.start_s, t_s) - 1
        return self.ids[max(k, 0)]

    def gt_at(self, object_id: str, t_s: float) -> str | None:
        """Receptacle of ``object_id`` in the latest scan at or before ``t_s``, or None (absent)."""
        return self.by_scan.get(self.scan_before(t_s), {}).get(object_id)

    def doors_of(self, scan_id: str) -> dict[str, bool]:
        """Door states of scan ``scan_id`` (unknown counts as open)."""
        st = self.door_by_scan.get(scan_id, {})
        return {d: bool(st.get(d, True)) for d in self.door_ids}

    def doors_at(self, t_s: float) -> dict[str, bool]:
        """Door states of the latest scan at or before ``t_s``."""
        return self.doors_of(self.scan_before(t_s))
