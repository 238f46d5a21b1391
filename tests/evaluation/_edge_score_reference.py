"""The per-edge scoring of main 97528cb (``_score`` of evaluation/_edge_run.py with the metric helpers of
metrics/_classification.py it called), kept as the reference of tests/evaluation/test_edge_score_shared.py."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

_EPS = 1e-8
_METRICS = ("mae", "balanced_accuracy", "f1", "sample_mae", "sample_balanced_accuracy", "sample_f1")


def _counts(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64],
            threshold: float) -> tuple[float, float, float, float]:
    pos = b >= threshold
    t = y == 1
    return (float(np.sum(w[t & pos])), float(np.sum(w[~t & pos])), float(np.sum(w[t & ~pos])),
            float(np.sum(w[~t & ~pos])))


def _mae(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64]) -> float:
    return float(np.sum(w * np.abs(y - b)) / np.sum(w))


def _bacc(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64], threshold: float,
          convention: str) -> float:
    tp, fp, fn, tn = _counts(y, b, w, threshold)
    if convention == "reference":
        return (tp / (tp + fn + _EPS) + tn / (tn + fp + _EPS)) / 2.0
    recalls = []
    if tp + fn > 0:
        recalls.append(tp / (tp + fn))
    if tn + fp > 0:
        recalls.append(tn / (tn + fp))
    return float(np.mean(recalls))


def _f1(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64], threshold: float, convention: str,
        zero_division: float) -> float:
    tp, fp, fn, _ = _counts(y, b, w, threshold)
    if convention == "reference":
        p = tp / (tp + fp + _EPS)
        r = tp / (tp + fn + _EPS)
        return 2.0 * p * r / (p + r + _EPS)
    den = 2.0 * tp + fp + fn
    return float(zero_division) if den == 0 else 2.0 * tp / den


def reference_score(y: NDArray[np.int64], b: NDArray[np.float64], w: NDArray[np.float64], cfg: Any
                    ) -> dict[str, float]:
    out = {m: float("nan") for m in _METRICS}
    y8 = y.astype(np.int8)
    if y.size:
        ones = np.ones_like(b)
        out["sample_mae"] = _mae(y8, b, ones)
        out["sample_balanced_accuracy"] = _bacc(y8, b, ones, cfg.threshold, cfg.sample_convention)
        out["sample_f1"] = _f1(y8, b, ones, cfg.threshold, cfg.sample_convention, 0.0)
    if np.sum(w) > 0:
        out["mae"] = _mae(y8, b, w)
        out["balanced_accuracy"] = _bacc(y8, b, w, cfg.threshold, cfg.convention)
        out["f1"] = _f1(y8, b, w, cfg.threshold, cfg.convention, 0.0)
    return out
