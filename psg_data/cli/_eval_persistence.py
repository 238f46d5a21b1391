"""``psg-eval --task persistence``: the Table I shaped run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from psg_data.cli._common import Progress
from psg_data.cli._eval_provenance import provenance

__all__ = ["run_persistence"]


def run_persistence(specs: list[Any], dataset: str | None, setting: str, labels: str, seeds: list[int], jobs: int,
                     out: Path, no_plots: bool, quiet: bool, *, scheduler: str | None = None,
                     rerun_file: Path | None = None, overwrite: bool = False) -> bool:
    from psg_data.cli._eval_inputs import persistence_tasks, require_hints, resolve_dataset
    from psg_data.evaluation import (
        choose_plot_edges,
        format_persistence_table,
        merge_results,
        plot_beliefs,
        plot_metric_bars,
        write_persistence_results,
    )

    choice = resolve_dataset(dataset, quiet=quiet)
    tasks, info = persistence_tasks(choice, labels=labels, seeds=seeds, quiet=quiet)
    require_hints(specs, tasks[0].estimator_hints, choice.label)
    n_edges = len(tasks[0].ground_truth)
    prog = Progress("evaluating", total=len(specs) * len(seeds) * n_edges, unit="edge runs", quiet=quiet)
    plot_edges = choose_plot_edges(tasks[0].ground_truth, k=4)
    if rerun_file is not None:  # every scored edge's beliefs are kept for the recording
        plot_edges = list(tasks[0].ground_truth)
    with _executor(jobs, scheduler) as executor:
        results = _evaluate(specs, tasks, seeds, setting, jobs, executor, prog, plot_edges)
    prog.close()
    result = results[0] if len(results) == 1 else merge_results(results)
    info = provenance({"task": "persistence", "dataset_label": choice.label, "labels": labels, **info,
                       "estimator_specs": {s.label: {"name": s.name, "settings": dict(s.settings)} for s in specs}})
    write_persistence_results(result, out, info=info)
    if rerun_file is not None:
        _save_beliefs(result, rerun_file, overwrite)
    if not no_plots:
        plot_beliefs(_plotted(result.traces, tasks[0].ground_truth), out / "belief.png", timezone=tasks[0].timezone)
        plot_metric_bars(result, out / "bars.png")
    click.echo(f"\nPersistence estimation on {choice.label} ({info.get('edges')} edges, labels {labels}, "
               f"{setting}, seeds {seeds[0]}..{seeds[-1]})")
    click.echo(format_persistence_table(result))
    if result.errors:
        click.echo(f"\n{len(result.errors)} problem(s) (see results.json 'errors'):", err=True)
        for e in result.errors[:20]:
            click.echo(f"error: {e.message}", err=True)
    return result.ok


def _plotted(traces: list[Any], truth: Any) -> list[Any]:
    """The traces of the edges the belief plot shows (all traces are kept when --rerun asks for them)."""
    from psg_data.evaluation import choose_plot_edges

    keep = set(choose_plot_edges(truth, k=4))
    return [t for t in traces if t.edge in keep]


def _save_beliefs(result: Any, path: Path, overwrite: bool) -> None:
    """The --rerun hook: beliefs of every estimator over time, per scored edge, first seed."""
    from psg_data.viewer import log_beliefs, recording

    with recording(path, application_id="psg-eval", overwrite=overwrite) as rec:
        n = log_beliefs(rec, result.traces)
    click.echo(f"beliefs of {len(result.estimators)} estimators on {n} edges written to {path}")


def _executor(jobs: int, scheduler: str | None) -> Any:
    """One executor for every task of the run (Dask or a local pool), or none for ``--jobs 1``."""
    import contextlib

    from psg_data._executors import open_executor

    if scheduler is None and jobs == 1:
        return contextlib.nullcontext(None)
    if jobs == -1:
        from psg_data._cpus import available_cpus

        jobs = available_cpus()
    return open_executor(jobs, scheduler)


def _evaluate(specs: list[Any], tasks: list[Any], seeds: list[int], setting: str, jobs: int, executor: Any,
              prog: Any, plot_edges: list[Any]) -> list[Any]:
    from psg_data.cli._eval_inputs import with_hints
    from psg_data.evaluation import RegistryFactory, evaluate_persistence

    offset = 0
    results = []
    run_seeds = [[s] for s in seeds] if len(tasks) > 1 else [seeds]
    for task, task_seeds in zip(tasks, run_seeds):
        factories = {s.label: RegistryFactory(s.name, with_hints(s, task.estimator_hints).settings) for s in specs}

        def progress(done: int, total: int, base: int = offset) -> None:
            prog.done = base + done
            prog.update(0)

        results.append(evaluate_persistence(
            factories, task.train_streams, task.test_streams, task.ground_truth, val_streams=task.val_streams,
            setting=setting, timezone=task.timezone, seeds=task_seeds, jobs=jobs, progress=progress,
            keep_predictions=plot_edges if task is tasks[0] else (), executor=executor))
        offset += len(specs) * len(task_seeds) * len(task.ground_truth)
    return results
