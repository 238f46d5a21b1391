"""Metrics and evaluation harnesses.

- Persistence metrics (:mod:`._classification`): :func:`mae`, :func:`balanced_accuracy`,
  :func:`f1` per sample (scikit-learn's shape and, by default, its convention) and
  :func:`time_integrated_mae`, :func:`time_integrated_balanced_accuracy`,
  :func:`time_integrated_f1` (trapezoid integrals over the ground-truth grid, by default the
  Perpetua reference's convention that the paper's Table I uses). Beliefs are binarised as
  present iff ``b >= 0.5``; ground-truth codes -1/-2 are excluded (:func:`mask_codes`).
- Navigation metrics: :func:`success_rate`, :func:`spl`, :func:`abort_rate`,
  :func:`distance_travelled`.
- Aggregation: :func:`summarize` -> :class:`Summary` (mean, std with ddof=1, seeded percentile
  bootstrap CI, n).
- The persistence task: :func:`evaluate_persistence` -> :class:`PersistenceResult`.
"""

from __future__ import annotations

from psg_data.metrics._aggregate import Summary, bootstrap_ci, summarize
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
from psg_data.metrics._dataset_task import DenseGroundTruth, PersistenceTask, persistence_task_from_dataset
from psg_data.metrics._report import (
    choose_plot_edges,
    format_persistence_table,
    plot_beliefs,
    plot_metric_bars,
    write_persistence_results,
)
from psg_data.metrics._persistence_task import (
    SAMPLE_METRICS,
    TIME_METRICS,
    WEEKDAY_NAMES,
    EdgeResult,
    EvaluationIssue,
    PersistenceResult,
    PredictionTrace,
    RegistryFactory,
    merge_results,
    WeekdayResult,
    evaluate_persistence,
)

__all__ = [
    "PRIVILEGED_CODES",
    "Convention",
    "mask_codes",
    "binarize",
    "trapezoid_weights",
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
    "Summary",
    "summarize",
    "bootstrap_ci",
    "TIME_METRICS",
    "SAMPLE_METRICS",
    "WEEKDAY_NAMES",
    "EvaluationIssue",
    "EdgeResult",
    "WeekdayResult",
    "PersistenceResult",
    "PredictionTrace",
    "RegistryFactory",
    "merge_results",
    "evaluate_persistence",
    "PersistenceTask",
    "format_persistence_table",
    "write_persistence_results",
    "plot_beliefs",
    "plot_metric_bars",
    "choose_plot_edges",
    "persistence_task_from_dataset",
    "DenseGroundTruth",
]
