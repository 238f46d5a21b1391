"""Statistics of a synthetic lab's schedules: how much a scan schedule can see and predict.

``psg-data lab-stats [--generator G] [--routine-strength R] [--dataset PATH]`` prints them as JSON
(RESULTS.md, section "The built-in lab"). Definitions (moving objects: their state changes at
least once over the dataset's scans; moving edges: (object, receptacle) pairs whose presence
changes):

* ``visits_unseen_by_timing``: share of visits (maximal stays of a moving object on one receptacle
  in the dataset's days) during which no scan starts;
* ``visits_seen_privileged`` (:func:`psg_data.labeling.visibility_statistics`, with ``--dataset``):
  share of visits with at least one privileged code 1 (visibility from the depth images);
* ``p_same_next_scan`` / ``_within_day`` / ``_overnight``: P(a moving object is on the same
  receptacle, or absent again, at the next scan), over consecutive scans, within a day (2 h later)
  and from the last scan of a day to the first of the next;
* ``time_of_week_share``: per moving edge, 1 - H(X | time-of-week slot) / H(X) for the binary
  presence X at scan times, the slot being (weekday, scan hour); the probabilities are estimated on
  ``sim_weeks`` simulated weeks of the same generator and seed (3 weeks of data would bias it
  upwards: 3 samples per slot); mean and range over the moving edges.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["schedule_statistics"]


def _entropy(p: NDArray[np.float64]) -> NDArray[np.float64]:
    p = np.clip(p, 1e-12, 1 - 1e-12)
    return -(p * np.log2(p) + (1 - p) * np.log2(1 - p))


def _scan_states(lab: Any, days: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """(T, O) receptacle index (-1 absent) at every scan slot (4 min after its start), day and slot."""
    from psg_data.synth._schedule import local_time_ns

    cfg = lab.config
    stamps, day, slot = [], [], []
    for d in range(days):
        date = cfg.date + dt.timedelta(days=d)
        for k, h in enumerate(cfg.scan_hours):
            stamps.append(local_time_ns(date, float(h), cfg.timezone) + 240 * 10**9)
            day.append(d)
            slot.append(k)
    t = np.asarray(stamps, np.int64)
    X = np.stack([lab.schedule.objects[o].at(t) for o in lab.schedule.object_ids], axis=1)
    return X, np.asarray(day), np.asarray(slot)


def schedule_statistics(config: Any = None, *, sim_weeks: int = 52) -> dict[str, Any]:
    """Timing, persistence and time-of-week statistics of a lab configuration (see the module docstring)."""
    from psg_data.synth._model import LabConfig, LabModel

    cfg = config or LabConfig()
    lab = LabModel(cfg)
    X, day, slot = _scan_states(lab, cfg.days)
    moving = [j for j in range(X.shape[1]) if len(np.unique(X[:, j])) > 1]
    same = X[1:, moving] == X[:-1, moving]
    night = day[1:] != day[:-1]
    scans_ns = np.array([p.start_ns for p in lab.scans], np.int64)
    visits = unseen = 0
    for j in moving:
        tl = lab.schedule.objects[lab.schedule.object_ids[j]]
        ends = np.append(tl.change_ns[1:], lab.schedule.end_ns)
        for a, b, s in zip(tl.change_ns, ends, tl.states):
            if s < 0:
                continue
            visits += 1
            unseen += not np.any((scans_ns >= a) & (scans_ns < b))
    long = LabModel(dataclasses.replace(cfg, days=7 * sim_weeks, train_days=None, shift=None))
    XL, dayL, slotL = _scan_states(long, 7 * sim_weeks)
    wd = np.array([(cfg.date + dt.timedelta(days=int(d))).weekday() for d in dayL])
    key = wd * len(cfg.scan_hours) + slotL
    shares = []
    for j in moving:
        for r in np.unique(X[:, j]):
            if r < 0:
                continue
            x = (XL[:, j] == r).astype(np.float64)
            h = float(_entropy(np.array([x.mean()]))[0])
            if not h > 1e-9:
                continue
            cond = sum((key == k).mean() * float(_entropy(np.array([x[key == k].mean()]))[0]) for k in np.unique(key))
            shares.append(1.0 - cond / h)
    sh = np.asarray(shares)
    return {
        "generator": cfg.generator, "routine_strength": cfg.routine_strength if cfg.generator == "steps-v2" else None,
        "moving_objects": len(moving), "moving_edges": int(sh.size), "visits": visits,
        "visits_unseen_by_timing": unseen / max(visits, 1),
        "p_same_next_scan": float(same.mean()), "p_same_next_scan_within_day": float(same[~night].mean()),
        "p_same_next_scan_overnight": float(same[night].mean()),
        "time_of_week_share_mean": float(sh.mean()), "time_of_week_share_min": float(sh.min()),
        "time_of_week_share_max": float(sh.max()), "sim_weeks": sim_weeks,
    }
