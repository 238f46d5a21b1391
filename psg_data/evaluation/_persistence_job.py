"""A whole persistence evaluation as ``psg-eval`` runs it: rows (the user's, the paper's, the references),
one dataset or several draws of a synthetic one, and the files and figures of the run.

- :func:`persistence_rows`: the estimator specs of a run and the role of each reference row;
- :func:`run_persistence_rows` on one :class:`PersistenceTask`;
- :func:`run_lab_draws`: ``--lab-seeds N``: N regenerated labs (or benchmark draws), one job per
  draw on an executor (:func:`psg_data._executors.open_executor`), merged into one result whose
  interval is the t-interval over draws;
- :func:`run_scene_datasets`: several datasets scored as draws of one benchmark (the navigation
  benchmark's 15 scenes): one job per scene, merged; the interval is the t-interval over the
  scenes and ``std`` the standard deviation across scenes (the paper's ±). Each scene's validation
  split (``scans.split == 'val'``, week 3) reaches ``fit`` as ``val_streams`` and is never scored;
- :func:`write_persistence_outputs`: the results schema, CSV files and the PNG figures.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from pathlib import Path
from typing import Any

from psg_data.errors import EvaluationError
from psg_data.evaluation._dataset_task import PersistenceTask
from psg_data.evaluation._hints import EstimatorSpec, with_hints, with_label_noise
from psg_data.evaluation._options import PersistenceOptions
from psg_data.evaluation._oracles import TruthFactory
from psg_data.evaluation._persistence_result import PersistenceResult, merge_results
from psg_data.evaluation._persistence_task import RegistryFactory, run_persistence_task, seeds_for
from psg_data.evaluation._references import PAPER_METHODS, persistence_references

__all__ = ["persistence_rows", "factories_for", "run_persistence_rows", "run_lab_draws", "write_persistence_outputs",
           "draw_task", "run_scene_datasets"]

Roles = dict[str, tuple[str, str]]


def persistence_rows(specs: Sequence[EstimatorSpec], hints: dict[str, Any], *, references: bool = True
                     ) -> tuple[list[EstimatorSpec], Roles]:
    """The rows of a run: the user's specs, then (with ``references``) the paper's comparison methods and
    the reference rows (ceiling, baselines, chance) not already given; and label -> (role, description).
    """
    out = list(specs)
    roles: Roles = {}
    if not references:
        return out, roles
    have = {s.label for s in out} | {s.name for s in out if not s.settings}
    out += [EstimatorSpec.of(m) for m in PAPER_METHODS if m not in have]
    for ref in persistence_references(hints):
        roles[ref.label] = (ref.role, ref.description)
        if ref.label not in have:
            out.append(ref.spec)
    return out, roles


def factories_for(specs: Sequence[EstimatorSpec], task: PersistenceTask) -> dict[str, Callable[..., Any]]:
    """Label -> picklable factory (registry estimators with the task's hints; ``ground_truth`` -> the truth)."""
    out: dict[str, Callable[..., Any]] = {}
    for s in specs:
        if s.name == "ground_truth":
            out[s.label] = TruthFactory(task.ground_truth)
        else:
            s2 = with_label_noise(with_hints(s, task.estimator_hints), str(task.info.get("labels_spec", "gt")))
            out[s.label] = RegistryFactory(s.name, s2.settings)
    return out


def run_persistence_rows(specs: Sequence[EstimatorSpec], task: PersistenceTask, options: PersistenceOptions, *,
                         jobs: int = 1, executor: Executor | None = None,
                         progress: Callable[[int, int], None] | None = None,
                         keep_predictions: Sequence[Any] = ()) -> PersistenceResult:
    """:func:`run_persistence_task` of these rows on one task."""
    return run_persistence_task(factories_for(specs, task), task, options, jobs=jobs, executor=executor,
                                progress=progress, keep_predictions=keep_predictions)


def draw_task(kind: str, seed: int, labels: str, label_seed: int = 0) -> PersistenceTask:
    """Draw ``seed`` of a synthetic dataset: ``lab`` (the built-in lab, no images; ``label_seed``: the seed
    of its ``noisy:P`` flips) or ``benchmark``.
    """
    from psg_data.evaluation._dataset_task import persistence_task_from_benchmark, persistence_task_from_lab

    if kind == "benchmark":
        if labels != "gt":
            raise EvaluationError(f"--labels {labels}: the persistence benchmark has its own noisy observations "
                                  "(P_M = P_F = 0.1); use --labels gt (the default)")
        return persistence_task_from_benchmark(seed)
    from psg_data.synth import LabConfig

    return persistence_task_from_lab(LabConfig(seed=int(seed)), labels=labels, seed=label_seed)


def _gather(fn: Callable[..., tuple[PersistenceResult, PersistenceTask | None]], calls: dict[int, tuple[Any, ...]],
            executor: Executor | None, progress: Callable[[int, int], None] | None
            ) -> tuple[dict[int, PersistenceResult], PersistenceTask | None]:
    """Run ``fn(*args)`` per key (inline, or one job each on ``executor``): results by key, the first task kept."""
    results: dict[int, PersistenceResult] = {}
    first: PersistenceTask | None = None
    if executor is None:
        for done, (key, args) in enumerate(calls.items(), 1):
            res, task = fn(*args)
            results[key], first = res, first or task
            if progress is not None:
                progress(done, len(calls))
        return results, first
    from concurrent.futures import as_completed

    futs = {executor.submit(fn, *args): key for key, args in calls.items()}
    for done, fut in enumerate(as_completed(futs), 1):
        res, task = fut.result()
        results[futs[fut]], first = res, first or task
        if progress is not None:
            progress(done, len(calls))
    return results, first


def _draw_job(kind: str, seed: int, labels: str, specs: Sequence[EstimatorSpec], options: PersistenceOptions,
              keep: bool, label_seed: int = 0) -> tuple[PersistenceResult, PersistenceTask | None]:
    """One draw, evaluated inline (runs in a worker process)."""
    from psg_data.evaluation._report import choose_plot_edges

    task = draw_task(kind, seed, labels, label_seed)
    kept = choose_plot_edges(task.ground_truth) if keep else ()
    res = run_persistence_rows(specs, task, options, keep_predictions=kept)
    return res, (task if keep else None)


def run_lab_draws(kind: str, seeds: Sequence[int], labels: str, specs: Sequence[EstimatorSpec],
                  options: PersistenceOptions, *, executor: Executor | None = None,
                  progress: Callable[[int, int], None] | None = None,
                  label_seed: int = 0) -> tuple[PersistenceResult, PersistenceTask]:
    """Evaluate the rows on every draw (``executor``: one job per draw; None: inline) and merge
    (``label_seed``: the seed of every draw's ``noisy:P`` flips).

    Returns:
        The merged result (summary: t-interval over the draws) and the first draw's task (its
        predictions are kept for the belief figure).
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise EvaluationError("--lab-seeds: no draw")
    calls = {s: (kind, s, labels, list(specs), options, k == 0, label_seed) for k, s in enumerate(seeds)}
    results, first = _gather(_draw_job, calls, executor, progress)
    assert first is not None
    merged = merge_results([results[s] for s in seeds]) if len(seeds) > 1 else results[seeds[0]]
    return merged, first


def _scene_job(path: str, draw: int, labels: str, specs: Sequence[EstimatorSpec], options: PersistenceOptions,
               keep: bool) -> tuple[PersistenceResult, PersistenceTask | None]:
    """One scene dataset, evaluated inline (runs in a worker process)."""
    from psg_data.evaluation._dataset_task import persistence_task_from_dataset
    from psg_data.evaluation._report import choose_plot_edges

    task = persistence_task_from_dataset(path, labels=labels)
    task.draw = int(draw)
    task.info["kind"] = "the navigation benchmark"
    kept = choose_plot_edges(task.ground_truth) if keep else ()
    res = run_persistence_rows(specs, task, options, keep_predictions=kept)
    return res, (task if keep else None)


def run_scene_datasets(paths: Sequence[Any], labels: str, specs: Sequence[EstimatorSpec], options: PersistenceOptions,
                       *, executor: Executor | None = None, progress: Callable[[int, int], None] | None = None
                       ) -> tuple[PersistenceResult, PersistenceTask]:
    """Evaluate the rows on every scene dataset (draw ``k`` = ``paths[k]``) and merge (module docstring).

    Returns:
        The merged result (t-interval over the scenes) and the first scene's task.
    """
    if not paths:
        raise EvaluationError("run_scene_datasets: no scene")
    jobs = [(str(p), k) for k, p in enumerate(paths)]
    calls = {k: (p, k, labels, list(specs), options, k == 0) for p, k in jobs}
    results, first = _gather(_scene_job, calls, executor, progress)
    assert first is not None
    ordered = [results[k] for _, k in jobs]
    merged = merge_results(ordered, draw_unit="scenes") if len(ordered) > 1 else ordered[0]
    return merged, first


def fit_counts(specs: Sequence[EstimatorSpec], task: PersistenceTask, options: PersistenceOptions) -> int:
    """How many (estimator, seed) fits a run makes (for progress totals)."""
    return sum(len(seeds_for(f, options.seeds)) for f in factories_for(specs, task).values())


def write_persistence_outputs(result: PersistenceResult, out: Path, *, info: dict[str, Any], roles: Roles,
                              timezone: str, plots: bool = True, executor: Executor | None = None) -> Any:
    """Write the results schema, the CSV files and (``plots``) belief.png, bars.png, horizon.png.

    With ``executor``, the figures are drawn there while this process writes the results
    (:mod:`psg_data.evaluation._persistence_figures`); the files are the same.

    Returns:
        The :class:`~psg_data.evaluation.EvalResults` written.
    """
    from psg_data.evaluation._persistence_figures import figure_calls, submit_figures, write_figures
    from psg_data.evaluation._report import persistence_results, write_persistence_results

    results = persistence_results(result, roles=roles, info=info)
    calls = figure_calls(result, results, roles, timezone) if plots else {}
    started = submit_figures(calls, executor)
    write_persistence_results(result, out, info=info, roles=roles, results=results)
    write_figures(calls, out, started)
    return results
