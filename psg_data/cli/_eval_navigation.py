"""``psg-eval --task navigation`` and ``--task doors`` (the work is in :mod:`psg_data.evaluation`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from psg_data.cli._common import Progress
from psg_data.cli._eval_provenance import provenance

__all__ = ["run_navigation_task", "run_doors_task", "navigation_options", "door_task_options", "print_problems"]


def navigation_options(protocol: str, *, labels: str, seeds: list[int], queries: int | None, setting: str,
                       delta: float, reachable_only: bool, door_belief: str | None, windows: str = "auto",
                       label_seed: int = 0) -> Any:
    """The :class:`~psg_data.navigation.NavigationOptions` of the command line (checked before any work)."""
    from psg_data.errors import EvaluationError
    from psg_data.navigation import NavigationOptions

    over: dict[str, Any] = {"labels": labels, "seeds": tuple(seeds), "setting": setting, "delta": delta,
                            "windows": _windows(windows), "label_seed": label_seed}
    if queries is not None:
        if protocol == "paper-real":
            raise EvaluationError("--queries: the paper-real protocol has 25 queries (10 static, 10 dynamic, 5 absent) "
                                  "per seed; use --seeds for more query sets")
        over["n_queries"] = queries
    if reachable_only:
        over["reachable_only"] = True
    if door_belief is not None:
        over["door_belief"] = door_belief.replace("-", "_")
    return NavigationOptions.preset(protocol, **over)


def _windows(text: str) -> str:
    if text not in ("auto", "none"):
        from psg_data.evaluation import parse_windows

        parse_windows(text, "UTC")  # syntax now; the dataset's timezone later
    return text


def door_task_options(*, labels: str, seeds: list[int], queries: int | None, setting: str = "adaptive",
                      windows: str = "auto", label_seed: int = 0) -> Any:
    """The :class:`~psg_data.navigation.DoorTaskOptions` of the command line."""
    from psg_data.errors import EvaluationError, LabelingError
    from psg_data.labeling import parse_source
    from psg_data.navigation import DoorTaskOptions

    try:
        parse_source(labels)
    except LabelingError as exc:
        raise EvaluationError(str(exc)) from None
    return DoorTaskOptions(labels=labels, seeds=tuple(seeds), n_queries=queries or 250, setting=setting,
                           windows=_windows(windows), label_seed=label_seed)


def _dataset(dataset: str | None, labels: str, quiet: bool, task: str) -> Any:
    """The dataset choice; the cached demo lab is labelled on first use with a stored source."""
    from psg_data.cli._eval_inputs import _label_demo_if_needed, resolve_dataset
    from psg_data.errors import EvaluationError

    if dataset in ("door-loop", "door-loop-lab"):
        raise EvaluationError(f"--dataset {dataset}: the door loop world is a unit-test world now; --task doors "
                              "runs on a dataset's own map (--dataset demo or a dataset path)")
    choice = resolve_dataset(dataset, quiet=quiet)
    if choice.kind != "dataset":
        raise EvaluationError(f"--task {task} needs a dataset with rooms, doors and receptacles (not the persistence "
                              "benchmark); use --dataset demo or a dataset path")
    kind = labels.split(":", 1)[0]
    if choice.label == "demo lab" and kind in ("privileged", "detections", "observed"):
        from psg_data.loaders import open_dataset

        assert choice.path is not None  # the demo lab is a dataset
        _label_demo_if_needed(open_dataset(choice.path), labels, quiet)
    return choice


def _require(specs: list[Any], choice: Any) -> None:
    from psg_data.cli._eval_inputs import dataset_hints, require_hints
    from psg_data.loaders import open_dataset

    require_hints(specs, dataset_hints(open_dataset(choice.path)), choice.label)


def run_navigation_task(specs: list[Any], dataset: str | None, options: Any, out: Path, no_plots: bool,
                        quiet: bool, *, references: bool = True, deltas: tuple[float, ...] = (),
                        table_format: str = "text") -> bool:
    """Object navigation on a dataset: SR / SPL / AR / DIST per method (the paper's navigation tables)."""
    from psg_data.evaluation._tables import print_results
    from psg_data.navigation._job import run_navigation_job

    choice = _dataset(dataset, options.labels, quiet, "navigation")
    _require(specs, choice)
    info = provenance({"task": "navigation", "dataset_label": choice.label, "dataset": str(choice.path)})
    with Progress("navigation: filters and episodes", unit="runs", quiet=quiet) as prog:
        prog.start()  # no count to give: the clock (a heartbeat line off a terminal) says it is working
        _, results = run_navigation_job(specs, choice.path, options, out, references=references, deltas=deltas,
                                        plots=not no_plots, info=info)
    if table_format == "text":
        click.echo("")
    print_results(results, fmt=table_format)
    return print_problems(results.errors)


def run_doors_task(specs: list[Any], dataset: str | None, options: Any, out: Path, no_plots: bool,
                   quiet: bool, *, references: bool = True, table_format: str = "text") -> bool:
    """Door navigation on a dataset's own map, and objects behind predicted-closed doors."""
    from psg_data.evaluation._tables import print_results
    from psg_data.navigation._job import run_door_job

    choice = _dataset(dataset, options.labels, quiet, "doors")
    _require(specs, choice)
    info = provenance({"task": "doors", "dataset_label": choice.label, "dataset": str(choice.path),
                       "estimator_specs": {s.label: {"name": s.name, "settings": dict(s.settings)} for s in specs}})
    steps = len(options.seeds) + int(options.objects)
    with Progress("doors: query sets and objects", total=steps, unit="steps", quiet=quiet) as prog:
        prog.start()

        def progress(done: int, _total: int) -> None:
            prog.done = done
            prog.update(0)

        _, results = run_door_job(specs, choice.path, options, out, references=references, plots=not no_plots,
                                  info=info, progress=progress)
    if table_format == "text":
        click.echo("")
    print_results(results, fmt=table_format)
    return print_problems(results.errors)


def print_problems(errors: list[dict[str, Any]]) -> bool:
    """List the estimators' failures on stderr (one ``error:`` line each, at most 20); True when there is none."""
    if errors:
        click.echo(f"\n{len(errors)} problem(s) (see results.json 'errors'):", err=True)
        for e in errors[:20]:
            click.echo(f"error: {e['message']}", err=True)
    return not errors
