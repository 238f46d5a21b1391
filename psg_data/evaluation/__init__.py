"""Evaluation harnesses: fit estimators, run the persistence, navigation and door tasks, aggregate, report.

- The persistence task: :func:`run_persistence_task` (a :class:`PersistenceTask` and one frozen
  :class:`PersistenceOptions`) and :func:`evaluate_persistence` (bare streams) ->
  :class:`PersistenceResult`. Tasks: :func:`persistence_task_from_dataset`,
  :func:`persistence_task_from_lab` (a synthetic lab without images, for ``--lab-seeds``),
  :func:`persistence_task_from_benchmark` (the Sec. V-A benchmark).
- Scoring windows and cadence: :class:`DailyWindows`, :func:`dataset_windows`,
  :func:`dataset_cadence_s`.
- Intervals: :func:`t_interval` (over repetitions), :func:`ratio_interval` /
  :func:`cluster_bootstrap` / :func:`cluster_jackknife` (over objects or queries), the cell
  record :class:`Summary`.
- Reference rows (ceiling, baselines, chance): :func:`persistence_references` and friends.
- One versioned results schema for every task: :class:`EvalResults` (tables of :class:`ResultRow`),
  :func:`save_results` / :func:`load_results` (what ``psg-eval compare`` and notebooks read),
  one table renderer (rich): :func:`render_table`, :func:`format_results`, :func:`print_results`.
- Navigation and doors: :func:`score_records` / :func:`summarise_navigation` (per-query terms, bootstrap
  over queries), :func:`navigation_results`, :func:`door_results`, :func:`plot_delta_sweep`.
- Persistence reports: :func:`persistence_results`, :func:`write_persistence_results`, the plots
  :func:`plot_beliefs`, :func:`plot_metric_bars`, :func:`plot_horizon`.

- Real long-term benchmarks (dense state rows, test periods): :func:`evaluate_state_benchmark`
  (any :class:`~psg_data.loaders.raw.StateBenchmark`, also one built from your own streams),
  :func:`run_state_benchmark` / :func:`state_rows` / :func:`summarize_state_run`,
  :class:`StateRunOptions`, :class:`PatrolPlan`, :data:`STATE_PROTOCOLS`.

The metric functions themselves are in :mod:`psg_data.metrics`.
"""

from __future__ import annotations

from psg_data.evaluation._aggregate import Summary, bootstrap_ci, summarize
from psg_data.evaluation._dataset_task import (
    DenseGroundTruth,
    PersistenceTask,
    lab_ground_truth,
    persistence_task_from_benchmark,
    persistence_task_from_dataset,
    persistence_task_from_lab,
)
from psg_data.evaluation._door_report import door_results, summarise_doors
from psg_data.evaluation._hints import EstimatorSpec, dataset_hints, require_hints, with_hints
from psg_data.evaluation._intervals import (
    Interval,
    cluster_bootstrap,
    cluster_jackknife,
    describe_interval,
    ratio_interval,
    t_interval,
)
from psg_data.evaluation._navigation_report import (
    choose_map_query,
    navigation_results,
    plot_delta_sweep,
    write_navigation_results,
)
from psg_data.evaluation._navigation_scores import query_terms, score_records, summarise_navigation
from psg_data.evaluation._options import PersistenceOptions
from psg_data.evaluation._persistence_plots import plot_beliefs, plot_horizon, plot_metric_bars
from psg_data.evaluation._persistence_result import PersistenceResult, merge_results, summarize_rows
from psg_data.evaluation._persistence_task import (
    RegistryFactory,
    evaluate_persistence,
    resolve_estimators,
    run_persistence_task,
    seeds_for,
)
from psg_data.evaluation._persistence_types import (
    SAMPLE_METRICS,
    TIME_METRICS,
    WEEKDAY_NAMES,
    BreakdownRow,
    EdgeResult,
    EvaluationIssue,
    PredictionTrace,
    WeekdayResult,
)
from psg_data.evaluation._references import (
    PAPER_METHODS,
    Reference,
    door_references,
    navigation_references,
    persistence_references,
)
from psg_data.evaluation._report import (
    choose_plot_edges,
    format_persistence_table,
    persistence_results,
    write_persistence_results,
)
from psg_data.evaluation._results import (
    SCHEMA_VERSION,
    EvalResults,
    MetricInfo,
    ResultRow,
    ResultTable,
    load_results,
    results_frame,
    save_results,
)
from psg_data.evaluation._state_benchmark import (
    StateRunOptions,
    evaluate_state_benchmark,
    run_state_benchmark,
    state_rows,
    summarize_state_run,
)
from psg_data.evaluation._state_protocols import STATE_PROTOCOLS, PatrolPlan
from psg_data.evaluation._tables import format_compare, format_results, format_table, print_results, render_table
from psg_data.evaluation._windows import (
    DailyWindows,
    dataset_cadence_s,
    dataset_windows,
    format_duration,
    parse_duration,
    parse_windows,
)

__all__ = [
    "Summary", "summarize", "bootstrap_ci", "Interval", "t_interval", "cluster_bootstrap", "cluster_jackknife",
    "ratio_interval", "describe_interval", "summarize_rows",
    "TIME_METRICS", "SAMPLE_METRICS", "WEEKDAY_NAMES", "EvaluationIssue", "EdgeResult", "BreakdownRow",
    "WeekdayResult", "PersistenceResult", "PredictionTrace", "RegistryFactory", "resolve_estimators", "seeds_for",
    "merge_results", "evaluate_persistence", "run_persistence_task", "PersistenceOptions",
    "StateRunOptions", "evaluate_state_benchmark", "run_state_benchmark", "state_rows", "summarize_state_run",
    "STATE_PROTOCOLS", "PatrolPlan",
    "PersistenceTask", "persistence_task_from_dataset", "persistence_task_from_lab", "persistence_task_from_benchmark",
    "lab_ground_truth", "DenseGroundTruth",
    "EstimatorSpec", "dataset_hints", "with_hints", "require_hints",
    "DailyWindows", "dataset_windows", "dataset_cadence_s", "parse_windows", "parse_duration", "format_duration",
    "format_persistence_table", "write_persistence_results", "persistence_results", "plot_beliefs", "plot_metric_bars",
    "plot_horizon", "choose_plot_edges",
    "Reference", "PAPER_METHODS", "persistence_references", "navigation_references", "door_references",
    "SCHEMA_VERSION", "EvalResults", "MetricInfo", "ResultRow", "ResultTable", "load_results", "save_results",
    "results_frame", "render_table", "format_table", "format_results", "print_results", "format_compare",
    "query_terms", "score_records", "summarise_navigation", "navigation_results", "write_navigation_results",
    "choose_map_query", "plot_delta_sweep", "door_results", "summarise_doors",
]
