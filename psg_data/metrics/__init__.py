"""Metrics: pure functions of arrays (scikit-learn's ``metric(y_true, y_pred, ...)`` shape).

- Persistence metrics (:mod:`._classification`): :func:`mae`, :func:`balanced_accuracy`,
  :func:`f1` per sample (scikit-learn's shape and, by default, its convention) and
  :func:`time_integrated_mae`, :func:`time_integrated_balanced_accuracy`,
  :func:`time_integrated_f1` (trapezoid integrals over the ground-truth grid, by default the
  Perpetua reference's convention that the paper's Table I uses; ``windows=`` bounds the integral
  by scoring windows, :func:`window_weights`). Beliefs are binarised as
  present iff ``b >= 0.5``; ground-truth codes -1/-2 are excluded (:func:`mask_codes`).
- Navigation metrics: :func:`success_rate`, :func:`spl`, :func:`abort_rate`,
  :func:`distance_travelled`.

Fitting estimators, running tasks, aggregating and reporting live in :mod:`psg_data.evaluation`
(which calls these functions; this package imports nothing from it).
"""

from __future__ import annotations

from psg_data.metrics._classification import (
    PRIVILEGED_CODES,
    Convention,
    balanced_accuracy,
    binarize,
    confusion_counts,
    f1,
    mae,
    mask_codes,
    span_weighted_mean,
    time_integrated_balanced_accuracy,
    time_integrated_f1,
    time_integrated_mae,
    trapezoid_weights,
)
from psg_data.metrics._navigation import abort_rate, distance_travelled, spl, success_rate
from psg_data.metrics._time_weights import check_windows, window_weights

__all__ = [
    "PRIVILEGED_CODES",
    "Convention",
    "mask_codes",
    "binarize",
    "trapezoid_weights",
    "window_weights",
    "check_windows",
    "confusion_counts",
    "mae",
    "balanced_accuracy",
    "f1",
    "time_integrated_mae",
    "time_integrated_balanced_accuracy",
    "time_integrated_f1",
    "span_weighted_mean",
    "success_rate",
    "spl",
    "abort_rate",
    "distance_travelled",
]
