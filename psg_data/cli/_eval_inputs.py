"""Inputs of ``psg-eval``: which dataset, which estimators (with settings), the persistence task."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from psg_data.errors import EstimatorError, EvaluationError
from psg_data.evaluation._hints import EstimatorSpec, dataset_hints, require_hints, with_hints

__all__ = ["EstimatorSpec", "parse_estimator_spec", "check_estimators", "with_hints", "DatasetChoice",
           "resolve_dataset", "persistence_task_for", "persistence_tasks", "dataset_hints", "require_hints",
           "available_hints", "BENCHMARK", "DEMO", "NAVIGATION_BENCHMARK"]

BENCHMARK = "persistence-benchmark"
DEMO = "demo"
NAVIGATION_BENCHMARK = "navigation-benchmark"


def parse_estimator_spec(text: str) -> EstimatorSpec:
    """``NAME`` or ``NAME:key=value,...`` with each value parsed and checked by the estimator's declarations.

    Runs before any data is read: an unknown name, an unknown setting, a value of the wrong type or
    out of range, or an empty setting list (``NAME:``) raise :class:`EstimatorError` naming it.
    """
    from psg_data.estimators import get_factory
    from psg_data.estimators._params import declared, parse_setting

    name, colon, rest = text.partition(":")
    name = name.strip()
    factory = get_factory(name)
    parts = [p.strip() for p in rest.split(",")] if colon else []
    if colon and not any(parts):
        raise EstimatorError(f"--estimator {text!r}: no settings after ':'; expected NAME or "
                             "NAME:key=value[,key=value]")
    declarations = declared(factory)
    valid = _setting_names(factory)
    settings = []
    for part in parts:
        key, eq, value = part.partition("=")
        if not eq or not key.strip().isidentifier():
            raise EstimatorError(f"--estimator {text!r}: expected NAME or NAME:key=value[,key=value], got {part!r}")
        settings.append((key.strip(), parse_setting(f"--estimator {text!r}", declarations, key.strip(), value, valid)))
    return EstimatorSpec(text, name, tuple(settings))


def _setting_names(factory: Any) -> list[str] | None:
    """The keyword settings ``factory`` accepts (None when it takes ``**kwargs`` we cannot see)."""
    names = getattr(factory, "_param_names", None)
    if callable(names):
        return list(names())
    import inspect

    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return None
    return [k for k, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY or p.default is not p.empty]


def check_estimators(specs: list[EstimatorSpec]) -> None:
    """Build every estimator once so that unknown names and bad settings fail before any work."""
    from psg_data.estimators import get_estimator

    for spec in specs:
        try:
            get_estimator(spec.name, **dict(spec.settings))
        except EstimatorError as exc:
            raise EstimatorError(f"--estimator {spec.label!r}: {exc}") from None
        except TypeError as exc:
            raise EstimatorError(f"--estimator {spec.label!r}: bad settings ({exc})") from None


@dataclass(frozen=True)
class DatasetChoice:
    kind: str  # "benchmark", "dataset" or "scenes" (a folder of scene datasets, e.g. the navigation benchmark)
    path: Path | None
    label: str


def resolve_dataset(value: str | None, *, quiet: bool) -> DatasetChoice:
    """``demo`` (default: the built-in lab, built once into the cache), ``persistence-benchmark``
    (the paper's Sec. V-A streams) or a dataset directory.
    """
    if value in (None, DEMO):
        from psg_data.cli._progress import Progress
        from psg_data.datasets import demo
        from psg_data.synth import LabConfig

        cfg = LabConfig()
        with Progress("building the demo lab (once)", total=cfg.days * len(cfg.scan_hours), unit="scans",
                      quiet=quiet) as prog:
            root = demo(progress=prog)
        return DatasetChoice("dataset", Path(root), "demo lab")
    if value == BENCHMARK:
        return DatasetChoice("benchmark", None, BENCHMARK)
    if value == NAVIGATION_BENCHMARK:
        from psg_data.cli._progress import Progress
        from psg_data.datasets import BUILTIN, NAVIGATION_BENCHMARK_SCENES

        with Progress("building the navigation benchmark (once)", total=NAVIGATION_BENCHMARK_SCENES, unit="scenes",
                      quiet=quiet) as prog:
            root = BUILTIN[NAVIGATION_BENCHMARK](progress=prog)
        return DatasetChoice("scenes", Path(root), NAVIGATION_BENCHMARK)
    path = Path(value)
    if not path.is_dir():
        raise EvaluationError(f"--dataset {value!r}: not a directory; expected a psg-dataset path, "
                              f"'{DEMO}', '{BENCHMARK}' or '{NAVIGATION_BENCHMARK}'")
    return DatasetChoice("dataset", path, str(path))


def available_hints(value: str | None) -> dict[str, Any]:
    """The estimator hints a dataset choice offers, without building anything (the demo lab is a
    synthetic lab with its generator model; the benchmark has schedules; a path: its manifest).
    """
    if value in (None, DEMO):
        return {"dataset": "<the demo lab>", "schedules": {}}
    if value == BENCHMARK:
        return {"schedules": {}}
    if value == NAVIGATION_BENCHMARK:
        return {"dataset": "<each scene>", "schedules": {}, "test_shift": True}
    path = Path(value)
    if not path.is_dir():
        return {}
    from psg_data.errors import PsgDataError
    from psg_data.loaders import open_dataset

    try:
        return dataset_hints(open_dataset(path))
    except PsgDataError:
        return {}


def persistence_task_for(choice: DatasetChoice, *, labels: str, quiet: bool) -> Any:
    """The :class:`~psg_data.evaluation.PersistenceTask` of a dataset choice (the benchmark: its draw 0)."""
    from psg_data.evaluation import persistence_task_from_benchmark, persistence_task_from_dataset

    if choice.kind == "benchmark":
        if labels != "gt":
            raise EvaluationError(f"--labels {labels}: the persistence benchmark has its own noisy observations "
                                  "(P_M = P_F = 0.1); use --labels gt (the default)")
        return persistence_task_from_benchmark(0)
    from psg_data.loaders import open_dataset

    assert choice.path is not None  # a dataset choice has a path
    ds = open_dataset(choice.path)
    if labels.split(":", 1)[0] in ("privileged", "detections") and choice.label == "demo lab":
        _label_demo_if_needed(ds, labels, quiet)
    task = persistence_task_from_dataset(ds, labels=labels)
    if choice.label == "demo lab":
        task.name = "the built-in lab (demo, lab seed 0)"
    return task


def persistence_tasks(choice: DatasetChoice, *, labels: str, seeds: list[int], quiet: bool) -> tuple[list[Any], dict]:
    """Former form of :func:`persistence_task_for` (one task in a list, and its ``info``), kept for scripts."""
    task = persistence_task_for(choice, labels=labels, quiet=quiet)
    return [task], dict(task.info)


def _label_demo_if_needed(ds: Any, labels: str, quiet: bool) -> None:
    """The cached demo lab is ours: label it on first use instead of asking the user to."""
    from psg_data.labeling import label_dataset, parse_source

    name = parse_source(labels).name
    if ds.has_table("labels") and name in set(ds.table("labels").column("source").to_pylist()):
        return
    import logging

    logging.getLogger(__name__).info("labelling the demo lab with source %s (once)", labels)
    label_dataset(ds.root, labels)
    ds.refresh()
