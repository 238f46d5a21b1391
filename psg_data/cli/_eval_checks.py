"""``psg-eval``'s settings checked before any data is read (each failure: one ``error:`` line, exit 1)."""

from __future__ import annotations

import math
from typing import Any

from psg_data.errors import EvaluationError
from psg_data.evaluation._hints import EstimatorSpec

__all__ = ["parse_deltas", "persistence_options", "check_lab_seeds", "check_task_estimators", "check_builtin_task",
           "check_protocol", "NAVIGATION_PROTOCOLS"]

NAVIGATION_PROTOCOLS = ("sim", "paper-real", "paper-sim-predictive", "paper-sim-adaptive")
"""``--protocol`` values that choose navigation queries (they mean nothing to the persistence and door tasks)."""
_TASK_ONLY = {"perpetua_star_oracle": ("persistence", "the training ground truth of the persistence task's streams "
                                                      "(navigation and door maps carry none)")}


def parse_deltas(text: str, task: str) -> tuple[float, ...]:
    """``--delta 0.2`` or a sweep ``0.05,0.1,0.2,0.3`` (navigation only)."""
    parts = [p.strip() for p in str(text).split(",") if p.strip()]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise EvaluationError(f"--delta {text!r}: expected a number in [0, 1] or a list like "
                              "0.05,0.1,0.2,0.3") from None
    if not values or any(not (math.isfinite(v) and 0.0 <= v <= 1.0) for v in values):
        raise EvaluationError(f"--delta {text!r}: expected numbers in [0, 1]")
    if len(values) > 1 and task != "navigation":
        raise EvaluationError(f"--delta {text!r}: a delta sweep is a navigation run (--task navigation)")
    if len(set(values)) != len(values):
        raise EvaluationError(f"--delta {text!r}: values must be distinct")
    return values


def persistence_options(*, setting: str, horizon: str, weighting: str, windows: str,
                        seeds: tuple[int, ...] | None) -> Any:
    """The :class:`~psg_data.evaluation.PersistenceOptions` of the command line (syntax checked now; ``auto``
    decided by the dataset later).
    """
    from psg_data.evaluation import PersistenceOptions, parse_windows

    if windows != "auto":
        parse_windows(windows, "UTC")  # syntax only; the dataset's timezone applies
    if setting == "predictive" and horizon not in ("auto", "0"):
        raise EvaluationError(f"--horizon {horizon}: the predictive setting applies no test observation; a forecast "
                              "horizon is a setting of --setting adaptive")
    if weighting == "reference" and windows != "auto":
        raise EvaluationError("--windows with --weighting reference: the plain trapezoid ignores scoring windows; "
                              "use --weighting windows (or auto)")
    return PersistenceOptions(setting=setting, horizon=horizon, weighting=weighting, windows=windows,
                              seeds="auto" if seeds is None else tuple(seeds))


def check_lab_seeds(lab_seeds: tuple[int, ...] | None, dataset: str | None, task: str, labels: str) -> None:
    """``--lab-seeds`` regenerates a synthetic dataset: the demo lab (labels gt / noisy) or the benchmark."""
    if lab_seeds is None:
        return
    if dataset not in (None, "demo", "persistence-benchmark"):
        raise EvaluationError(f"--lab-seeds: {dataset} is a fixed dataset; --lab-seeds regenerates a synthetic one "
                              "(--dataset demo, the built-in lab, or persistence-benchmark)")
    if task != "persistence":
        raise EvaluationError(f"--lab-seeds: regenerated labs are scored by the persistence task, not --task {task} "
                              "(build labs with `psg-data synth OUT --seed K` and pass them with --dataset)")
    if labels.split(":", 1)[0] not in ("gt", "noisy"):
        raise EvaluationError(f"--lab-seeds with --labels {labels}: a regenerated lab is drawn without images, so only "
                              "gt and noisy:P labels exist; build it (psg-data synth) and label it for other sources")


def check_builtin_task(dataset: str | None, task: str, lab_seeds: tuple[int, ...] | int | None, *,
                       protocol: str = "sim", quick: bool = False) -> None:
    """The navigation benchmark takes the persistence task and the paper-sim navigation protocols (and
    those protocols take only the navigation benchmark).
    """
    sim = protocol.startswith("paper-sim")
    if quick and not (task == "navigation" and sim):
        raise EvaluationError("--quick: the small form of a paper-sim protocol (--task navigation --dataset "
                              "navigation-benchmark --protocol paper-sim-predictive|paper-sim-adaptive)")
    if task == "navigation" and sim and dataset != "navigation-benchmark":
        raise EvaluationError(f"--protocol {protocol}: the simulation protocols run on the benchmark's houses; use "
                              "--dataset navigation-benchmark")
    if dataset != "navigation-benchmark":
        return
    if task == "navigation" and not sim:
        raise EvaluationError(f"--protocol {protocol} on navigation-benchmark: its navigation protocols are "
                              "paper-sim-predictive and paper-sim-adaptive; pass one scene (--dataset "
                              "<cache>/navigation-benchmark-*/scene_00) to the lab protocols")
    if task not in ("persistence", "navigation"):
        raise EvaluationError(f"--task {task} on navigation-benchmark: the benchmark takes --task persistence and "
                              "--task navigation (paper-sim protocols); pass one scene (--dataset "
                              "<cache>/navigation-benchmark-*/scene_00) to the door task")
    if lab_seeds is not None:
        raise EvaluationError("--lab-seeds with navigation-benchmark: its 15 scenes are the draws already")


def check_task_estimators(specs: list[EstimatorSpec], task: str) -> None:
    """Refuse estimators that cannot run on the task at all (before any data is read)."""
    for s in specs:
        need = _TASK_ONLY.get(s.name)
        if need is not None and task != need[0] and not dict(s.settings).get("prior"):
            raise EvaluationError(f"--estimator {s.label!r}: {s.name} needs {need[1]}; use it with --task {need[0]}")


def check_protocol(task: str, protocol: str, *, given: bool) -> None:
    """Refuse a navigation protocol given with a task that has no navigation queries (persistence, doors);
    other values are left to the task that takes them.
    """
    if given and task in ("persistence", "doors") and protocol in NAVIGATION_PROTOCOLS:
        raise EvaluationError(f"--protocol {protocol}: a navigation protocol (--task navigation); --task {task} "
                              "does not use it")
