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
    """Build every estimator once so that unknown names and bad settings fail before any work.

    Settings an estimator does not declare (``_parameters``; a plugin's, typically) cannot be
    checked by type: with such a setting the estimator also makes a short fit and prediction on
    :func:`~psg_data.estimators.conformance_streams`, so that a bad value fails here, once, in one
    line, and not on every edge of the run.
    """
    from psg_data.estimators import get_estimator
    from psg_data.estimators._guard import guarded_call, isolate
    from psg_data.estimators._params import declared

    for spec in specs:
        try:  # a plugin's __init__ or get_params that raises or exits: one line (guarded_call)
            est = guarded_call(spec.name, "__init__", lambda s=spec: get_estimator(s.name, **dict(s.settings)),
                               passthrough=(EstimatorError, TypeError))
            guarded_call(spec.name, "get_params", est.get_params)
        except EstimatorError as exc:
            raise EstimatorError(f"--estimator {spec.label!r}: {exc}") from None
        except TypeError as exc:
            raise EstimatorError(f"--estimator {spec.label!r}: bad settings ({exc})") from None
        undeclared = [k for k, _ in spec.settings if k not in declared(est)]
        if undeclared:
            _trial_fit(spec, isolate(est, spec.label), undeclared)


def _trial_fit(spec: EstimatorSpec, est: Any, undeclared: list[str]) -> None:
    """A short fit and prediction with the settings the estimator does not declare (one line if it fails)."""
    import numpy as np

    from psg_data.estimators import conformance_streams

    streams = conformance_streams(days=3)
    try:
        est.fit(streams, timezone="UTC")
        f = est.make_filter(streams[0].edge)
        f.update_many(streams[0].t_s, streams[0].y)
        p = np.asarray(f.predict(streams[0].t_s[-1:] + 3600.0), dtype=np.float64)
    except Exception as exc:  # noqa: BLE001 - whatever the plugin raises, said once
        text = " ".join(str(exc).split())
        raise EstimatorError(f"--estimator {spec.label!r}: setting {', '.join(undeclared)} is not declared by "
                             f"{spec.name} and a trial fit with it fails ({type(exc).__name__}: {text}); check its "
                             "value (a plugin declares its settings in _parameters to have them checked by type)"
                             ) from None
    if not np.all(np.isfinite(p)):
        raise EstimatorError(f"--estimator {spec.label!r}: setting {', '.join(undeclared)} is not declared by "
                             f"{spec.name} and a trial fit with it predicts {p.tolist()}; check its value")


@dataclass(frozen=True)
class DatasetChoice:
    kind: str  # "benchmark", "dataset" or "scenes" (a folder of scene datasets, e.g. the navigation benchmark)
    path: Path | None
    label: str


def resolve_dataset(value: str | None, *, quiet: bool) -> DatasetChoice:
    """``demo`` (default: the built-in lab, built once into the cache), ``persistence-benchmark``
    (the paper's Sec. V-A streams), ``navigation-benchmark`` (the 15 house scenes) or a dataset directory.
    """
    from psg_data.datasets import BUILTIN

    name = DEMO if value is None else value
    if name == BENCHMARK:
        return DatasetChoice("benchmark", None, BENCHMARK)
    if name == NAVIGATION_BENCHMARK and not Path(name).is_dir():
        from psg_data.cli._progress import Progress
        from psg_data.datasets import NAVIGATION_BENCHMARK_SCENES, navigation_benchmark

        with Progress("building the navigation benchmark (once)", total=NAVIGATION_BENCHMARK_SCENES, unit="scenes",
                      quiet=quiet) as prog:
            root = navigation_benchmark(progress=prog)
        return DatasetChoice("scenes", Path(root), NAVIGATION_BENCHMARK)
    entry = BUILTIN.get(name)
    if entry is not None and entry.build is not None and not Path(name).is_dir():
        from psg_data.cli._common import dataset_path

        root = dataset_path(name, command="psg-eval --dataset", quiet=quiet)
        return DatasetChoice("dataset", root, "demo lab" if name == DEMO else name)
    path = Path(name)
    if not path.is_dir():
        raise EvaluationError(f"--dataset {value!r}: not a directory; expected a psg-dataset path or one of "
                              f"{', '.join(repr(n) for n in BUILTIN)}")
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


def persistence_task_for(choice: DatasetChoice, *, labels: str, quiet: bool, label_seed: int = 0) -> Any:
    """The :class:`~psg_data.evaluation.PersistenceTask` of a dataset choice (the benchmark: its draw 0);
    ``label_seed``: the seed of the ``noisy:P`` flips.
    """
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
    task = persistence_task_from_dataset(ds, labels=labels, seed=label_seed)
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
