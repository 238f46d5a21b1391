"""Evaluation harnesses: fit estimators, run the persistence, navigation and door tasks, aggregate, report.

- The persistence task: :func:`evaluate_persistence` -> :class:`PersistenceResult`; its inputs
  :class:`PersistenceTask` (:func:`persistence_task_from_dataset`).
- Aggregation: :func:`summarize` -> :class:`Summary`.
- Reports: :func:`format_persistence_table`, :func:`write_persistence_results`, the plots
  :func:`plot_beliefs`, :func:`plot_metric_bars`.

The metric functions themselves are in :mod:`psg_data.metrics`.
"""

from __future__ import annotations

from psg_data.evaluation._aggregate import Summary, bootstrap_ci, summarize
from psg_data.evaluation._dataset_task import DenseGroundTruth, PersistenceTask, persistence_task_from_dataset
from psg_data.evaluation._persistence_task import (
    SAMPLE_METRICS,
    TIME_METRICS,
    WEEKDAY_NAMES,
    EdgeResult,
    EvaluationIssue,
    PersistenceResult,
    PredictionTrace,
    RegistryFactory,
    WeekdayResult,
    evaluate_persistence,
    merge_results,
)
from psg_data.evaluation._report import (
    choose_plot_edges,
    format_persistence_table,
    plot_beliefs,
    plot_metric_bars,
    write_persistence_results,
)

__all__ = [
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
