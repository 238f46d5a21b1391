"""Inputs of ``psg-eval``: which dataset, which estimators (with settings), which tasks per seed."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EstimatorError, EvaluationError

__all__ = ["EstimatorSpec", "parse_estimator_spec", "check_estimators", "with_hints", "DatasetChoice", "resolve_dataset",
           "persistence_tasks", "dataset_hints", "require_hints"]

BENCHMARK = "persistence-benchmark"
DEMO = "demo"


@dataclass(frozen=True)
class EstimatorSpec:
    """``NAME`` or ``NAME:key=value,key=value`` (values are Python literals, else strings)."""

    label: str
    name: str
    settings: tuple[tuple[str, Any], ...] = ()


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
        raise EstimatorError(f"--estimator {text!r}: no settings after ':'; expected NAME or NAME:key=value[,key=value]")
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


def with_hints(spec: EstimatorSpec, hints: dict[str, Any]) -> EstimatorSpec:
    """``spec`` plus the task's hints that the estimator accepts and the user did not set."""
    from psg_data.estimators import get_estimator

    if not hints:
        return spec
    params = get_estimator(spec.name, **dict(spec.settings)).get_params()
    given = dict(spec.settings)
    extra = [(k, v) for k, v in hints.items() if k in params and k not in given and params[k] is None]
    return EstimatorSpec(spec.label, spec.name, spec.settings + tuple(extra)) if extra else spec


def dataset_hints(ds: Any) -> dict[str, Any]:
    """Estimator settings a dataset provides: a synthetic dataset with its stored generator model
    (``generator/process.json``) gives ``dataset`` (its path, for ``process_oracle``) and
    ``schedules`` (its routines in the paper's LLM output format, for the schedule prior)."""
    extra = ds.info.extra
    rel = extra.get("process_file")
    if extra.get("generator") != "psg_data.synth" or not rel or not (ds.root / rel).is_file():
        return {}
    from psg_data.synth._process import llm_schedules, load_process

    proc = load_process(ds.root)
    return {"dataset": str(ds.root), "schedules": {f"{o}/{r}": v for (o, r), v in llm_schedules(proc).items()}}


_NEEDS = {"process_oracle": ("dataset", "a synthetic dataset whose manifest names its generator model "
                                        "(psg-data synth, generator steps-v2)"),
          "perpetua_star_schedule": ("schedules", "schedules in the LLM output format (the persistence benchmark "
                                                  "and psg-data synth datasets provide them)")}


def require_hints(specs: list[EstimatorSpec], hints: dict[str, Any], dataset_label: str) -> None:
    """Refuse, before any work, estimators that need a setting the dataset cannot provide."""
    for spec in specs:
        need = _NEEDS.get(spec.name)
        if need is None:
            continue
        key, what = need
        given = dict(spec.settings)
        if given.get(key) is None and hints.get(key) is None and not (key == "dataset" and given.get("model")):
            raise EvaluationError(f"--estimator {spec.label!r}: {spec.name} needs {what}; {dataset_label} has none")


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
    kind: str  # "benchmark" or "dataset"
    path: Path | None
    label: str


def resolve_dataset(value: str | None, *, quiet: bool) -> DatasetChoice:
    """``demo`` (default: the built-in lab, built once into the cache), ``persistence-benchmark``
    (the paper's Sec. V-A streams) or a dataset directory."""
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
    path = Path(value)
    if not path.is_dir():
        raise EvaluationError(f"--dataset {value!r}: not a directory; expected a psg-dataset path, "
                              f"'{DEMO}' or '{BENCHMARK}'")
    return DatasetChoice("dataset", path, str(path))


def _synth_dense_ground_truth(ds: Any, step_s: float) -> Any:
    """Dense ground truth of a synthetic lab on a grid of ``step_s`` aligned with the clock,
    restricted to the daily scanning hours."""
    from zoneinfo import ZoneInfo

    import pandas as pd

    from psg_data.synth import LabModel

    lab = LabModel.from_dataset(ds)
    hours = list(ds.info.extra.get("scan_hours") or [9, 11, 13, 15])
    first_h, last_h = min(hours), max(hours) + 2

    step_ns = int(round(step_s * 1e9))

    def dense(start_ns: int, end_ns: int) -> tuple[np.ndarray, dict]:
        # grid aligned with whole multiples of step_s (local quarter hours for 900 s), so that a
        # state changing at a step start (09:00, 11:00, ...) changes on a grid point, not between two
        d = lab.schedule.dense(step_s, start_ns - start_ns % step_ns, end_ns)
        local = pd.to_datetime(d.stamps_ns, utc=True).tz_convert(ZoneInfo(ds.info.timezone))
        hod = local.hour.to_numpy() + local.minute.to_numpy() / 60.0
        keep = (hod >= first_h) & (hod <= last_h)
        stamps = d.stamps_ns[keep]
        objs = d.objects[keep]
        states = {}
        for j, o in enumerate(d.object_ids):
            for i, r in enumerate(d.receptacle_ids):
                states[(o, r)] = (objs[:, j] == i).astype(np.int64)
        return stamps, states

    return dense


def persistence_tasks(choice: DatasetChoice, *, labels: str, seeds: list[int], quiet: bool) -> tuple[list[Any], dict]:
    """One :class:`~psg_data.evaluation.PersistenceTask` per seed (benchmark: one draw per seed;
    datasets: the same task, seeds vary the estimators) and a description for results.json."""
    from psg_data.estimators import PAPER_SETTINGS
    from psg_data.evaluation import PersistenceTask, persistence_task_from_dataset

    if choice.kind == "benchmark":
        from psg_data.synth import make_persistence_benchmark

        if labels != "gt":
            raise EvaluationError(f"--labels {labels}: the persistence benchmark has its own noisy observations "
                                  "(P_M = P_F = 0.1); use --labels gt (the default)")
        tasks = []
        for s in seeds:
            bm = make_persistence_benchmark(seed=s)
            tasks.append(PersistenceTask(
                name=BENCHMARK, train_streams=bm.train_streams, test_streams=bm.test_streams,
                ground_truth=dict(bm.test_truth), timezone=bm.timezone, val_streams=bm.val_streams,
                info={"dataset": BENCHMARK, "seed": s, "p_m": bm.p_m, "p_f": bm.p_f, "shift": bm.shift,
                      "edges": len(bm.edges), "ground_truth": "dense 60 s grid over the test week",
                      "split": "week 0 validation, weeks 1-4 train, week 5 test"},
                # the paper's Sec. V-A settings (gamma per observation, alpha0 per minute, 1000
                # FreMEn periods) for every estimator that leaves them to the data's cadence
                estimator_hints={"schedules": bm.schedules, **PAPER_SETTINGS}))
        return tasks, {"dataset": BENCHMARK, "per_seed_draws": True, **{k: v for k, v in tasks[0].info.items()
                                                                         if k not in ("seed",)}}
    from psg_data.loaders import open_dataset

    ds = open_dataset(choice.path)
    if labels != "gt" and choice.label == "demo lab":
        _label_demo_if_needed(ds, labels, quiet)
    dense = None
    if ds.info.extra.get("generator") == "psg_data.synth":
        dense = _synth_dense_ground_truth(ds, step_s=900.0)
    task = persistence_task_from_dataset(ds, labels=labels, dense_ground_truth=dense)
    task.estimator_hints = dataset_hints(ds)
    return [task], {**task.info, "per_seed_draws": False}


def _label_demo_if_needed(ds: Any, labels: str, quiet: bool) -> None:
    """The cached demo lab is ours: label it on first use instead of asking the user to."""
    from psg_data.labeling import label_dataset, parse_source

    name = parse_source(labels).name
    if ds.has_table("labels") and name in set(ds.table("labels").column("source").to_pylist()):
        return
    import logging

    logging.getLogger(__name__).info("labelling the demo lab with source %s (once)", labels)
    label_dataset(ds.root, labels)
    ds._arrow.clear()
