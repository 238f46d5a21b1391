"""``psg-eval --task persistence``: the Table I shaped run (the work is in :mod:`psg_data.evaluation`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from psg_data.cli._common import Progress
from psg_data.cli._eval_provenance import provenance

__all__ = ["run_persistence"]


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


def _one_dataset(specs: list[Any], choice: Any, options: Any, labels: str, jobs: int, executor: Any,
                 quiet: bool, references: bool, keep_all: bool, label_seed: int) -> tuple[Any, Any, dict[str, Any]]:
    from psg_data.cli._eval_inputs import persistence_task_for, require_hints
    from psg_data.evaluation._persistence_job import fit_counts, persistence_rows, run_persistence_rows
    from psg_data.evaluation._report import choose_plot_edges

    task = persistence_task_for(choice, labels=labels, quiet=quiet, label_seed=label_seed)
    require_hints(specs, task.estimator_hints, choice.label)
    rows, roles = persistence_rows(specs, task.estimator_hints, references=references)
    total = fit_counts(rows, task, options) * len(task.ground_truth)
    keep = list(task.ground_truth) if keep_all else choose_plot_edges(task.ground_truth, k=4)
    with Progress("evaluating", total=total, unit="edge runs", quiet=quiet) as prog:
        def progress(done: int, _total: int) -> None:
            prog.done = done
            prog.update(0)

        result = run_persistence_rows(rows, task, options, jobs=jobs,
                                      executor=executor, progress=progress, keep_predictions=keep)
    return result, task, roles


def _scenes(specs: list[Any], choice: Any, options: Any, labels: str, executor: Any,
            quiet: bool, references: bool) -> tuple[Any, Any, dict[str, Any]]:
    """A folder of scene datasets (the navigation benchmark): each scene a draw, one job per scene."""
    from psg_data.cli._eval_inputs import available_hints
    from psg_data.datasets import navigation_benchmark_scenes
    from psg_data.evaluation._persistence_job import persistence_rows, run_scene_datasets

    paths = navigation_benchmark_scenes(choice.path)
    rows, roles = persistence_rows(specs, available_hints(choice.label), references=references)
    with Progress(f"evaluating {len(paths)} scenes", total=len(paths), unit="scenes", quiet=quiet) as prog:
        def progress(done: int, _total: int) -> None:
            prog.done = done
            prog.update(0)

        result, task = run_scene_datasets(paths, labels, rows, options, executor=executor, progress=progress)
    return result, task, roles


def _lab_draws(specs: list[Any], choice: Any, options: Any, labels: str, lab_seeds: tuple[int, ...],
               executor: Any, quiet: bool, references: bool, label_seed: int) -> tuple[Any, Any, dict[str, Any]]:
    from psg_data.evaluation._persistence_job import draw_task, persistence_rows, run_lab_draws

    kind = "benchmark" if choice.kind == "benchmark" else "lab"
    hints = draw_task(kind, 0, labels).estimator_hints if kind == "lab" else {"schedules": {}}
    rows, roles = persistence_rows(specs, hints, references=references)
    with Progress(f"evaluating {len(lab_seeds)} regenerated {'labs' if kind == 'lab' else 'benchmark draws'}",
                  total=len(lab_seeds), unit="draws", quiet=quiet) as prog:
        def progress(done: int, _total: int) -> None:
            prog.done = done
            prog.update(0)

        result, task = run_lab_draws(kind, lab_seeds, labels, rows, options, executor=executor,
                                     progress=progress, label_seed=label_seed)
    return result, task, roles


def run_persistence(specs: list[Any], dataset: str | None, options: Any, labels: str, jobs: int, out: Path,
                    no_plots: bool, quiet: bool, *, references: bool = True, lab_seeds: tuple[int, ...] | None = None,
                    scheduler: str | None = None, rerun_file: Path | None = None, overwrite: bool = False,
                    label_seed: int = 0, table_format: str = "text") -> bool:
    """Run, write the results schema and files, draw the figures, print the table; False when a row had errors."""
    from psg_data.cli._eval_inputs import resolve_dataset
    from psg_data.evaluation._persistence_job import write_persistence_outputs
    from psg_data.evaluation._tables import print_results

    if lab_seeds is not None:
        choice = resolve_dataset(dataset, quiet=quiet) if dataset == "persistence-benchmark" else _lab_choice()
    else:
        choice = resolve_dataset(dataset, quiet=quiet)
    # one executor for the run and its figures; its workers start (import) while the dataset is read
    with _executor(jobs, scheduler) as executor:
        if lab_seeds is not None:
            result, task, roles = _lab_draws(specs, choice, options, labels, lab_seeds, executor, quiet, references,
                                             label_seed)
        elif choice.kind == "scenes":
            result, task, roles = _scenes(specs, choice, options, labels, executor, quiet, references)
        else:
            result, task, roles = _one_dataset(specs, choice, options, labels, jobs, executor, quiet, references,
                                               keep_all=rerun_file is not None, label_seed=label_seed)
        info = provenance({"task": "persistence", "dataset_label": choice.label, "labels": labels, **task.info,
                           "lab_seeds": None if lab_seeds is None else list(lab_seeds),
                           "estimator_specs": {s.label: {"name": s.name, "settings": dict(s.settings)}
                                               for s in specs}})
        results = write_persistence_outputs(result, out, info=info, roles=roles, timezone=task.timezone,
                                            plots=not no_plots, executor=executor)
    if rerun_file is not None:
        _save_beliefs(result, rerun_file, overwrite)
    if table_format == "text":
        click.echo("")
    print_results(results, fmt=table_format)
    if result.errors:
        click.echo(f"\n{len(result.errors)} problem(s) (see results.json 'errors'):", err=True)
        for e in result.errors[:20]:
            click.echo(f"error: {e.message}", err=True)
    return result.ok


def _lab_choice() -> Any:
    from psg_data.cli._eval_inputs import DatasetChoice

    return DatasetChoice("lab", None, "regenerated labs")


def _save_beliefs(result: Any, path: Path, overwrite: bool) -> None:
    """The --rerun hook: beliefs of every estimator over time, per scored edge, first seed."""
    from psg_data.viewer import beliefs_blueprint, log_beliefs, recording

    with recording(path, application_id="psg-eval", overwrite=overwrite,
                   blueprint=beliefs_blueprint(result.traces)) as rec:
        n = log_beliefs(rec, result.traces)
    click.echo(f"beliefs of {len(result.estimators)} estimators on {n} edges written to {path}")
