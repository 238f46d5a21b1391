"""What a dataset offers estimators (hints), and the up-front refusal of estimators it cannot serve.

A synthetic dataset with its stored generator model gives ``dataset`` (its path, for
``process_oracle``) and ``schedules`` (its routines in the paper's LLM output format, for the
schedule prior); a lab drawn without images gives ``process`` instead of ``dataset``; a dataset
whose process has a test-time regime (the procedural houses) also gives ``test_shift`` (True),
which adds the ``process_oracle:model=train`` reference row; the persistence
benchmark gives ``schedules``. :func:`with_hints` adds a hint to an estimator's settings when the
estimator has that setting, the user did not set it and its value is None. :func:`require_hints`
refuses, before any work, an estimator that needs a hint the dataset cannot give.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from psg_data.errors import EstimatorError, EvaluationError

__all__ = ["EstimatorSpec", "dataset_hints", "with_hints", "require_hints", "NEEDS", "label_noise", "with_label_noise"]


@dataclass(frozen=True)
class EstimatorSpec:
    """``NAME`` or ``NAME:key=value,key=value`` (parsed by ``psg_data.cli._eval_inputs.parse_estimator_spec``)."""

    label: str
    name: str
    settings: tuple[tuple[str, Any], ...] = ()

    @staticmethod
    def of(name: str, **settings: Any) -> EstimatorSpec:
        """The spec of registry name ``name`` with ``settings`` (label ``name:key=value,...``)."""
        label = name + (":" + ",".join(f"{k}={v}" for k, v in settings.items()) if settings else "")
        return EstimatorSpec(label, name, tuple(settings.items()))


def dataset_hints(ds: Any) -> dict[str, Any]:
    """Estimator settings a dataset provides (module docstring)."""
    extra = ds.info.extra
    rel = extra.get("process_file")
    if not str(extra.get("generator", "")).startswith("psg_data.synth") or not rel or not (ds.root / rel).is_file():
        return {}
    from psg_data.schemas._generator_model import load_process
    from psg_data.synth._process import llm_schedules

    proc = load_process(ds.root)
    schedules = {f"{o}/{r}": v for (o, r), v in llm_schedules(proc).items()}
    out: dict[str, Any] = {"dataset": str(ds.root), "schedules": schedules}
    if proc.regimes:
        out["test_shift"] = True
    return out


def with_hints(spec: EstimatorSpec, hints: dict[str, Any]) -> EstimatorSpec:
    """``spec`` plus the task's hints that the estimator accepts and the user did not set."""
    from psg_data.estimators import get_estimator
    from psg_data.estimators._guard import build

    if not hints:
        return spec
    try:  # guarded: a plugin's failure here is reported by the task, not raised
        params = build(spec.name, lambda: get_estimator(spec.name, **dict(spec.settings))).get_params()
    except EstimatorError:
        return spec
    given = dict(spec.settings)
    extra = [(k, v) for k, v in hints.items() if k in params and k not in given and params[k] is None]
    return EstimatorSpec(spec.label, spec.name, spec.settings + tuple(extra)) if extra else spec


def label_noise(labels: str) -> tuple[float, float] | None:
    """(P_M, P_F) of a ``noisy:P[,P_F]`` label source, else None."""
    from psg_data.errors import LabelingError
    from psg_data.labeling import parse_source

    try:
        spec = parse_source(labels)
    except LabelingError:
        return None
    return (float(spec.p_m), float(spec.p_f)) if spec.kind == "noisy" else None


def with_label_noise(spec: EstimatorSpec, labels: str) -> EstimatorSpec:
    """The ceiling knows the data's noise model: ``process_oracle`` on ``noisy:P`` labels gets
    ``p_m`` / ``p_f`` of the source unless the user set them (learned estimators never do).
    """
    noise = label_noise(labels)
    if spec.name != "process_oracle" or noise is None:
        return spec
    given = dict(spec.settings)
    extra = tuple((k, v) for k, v in zip(("p_m", "p_f"), noise) if k not in given)
    return EstimatorSpec(spec.label, spec.name, spec.settings + extra) if extra else spec


NEEDS: dict[str, tuple[tuple[str, ...], str]] = {
    "process_oracle": (("dataset", "process"), "a synthetic dataset with its stored generator model (psg-data synth, "
                                             "generator steps-v2)"),
    "perpetua_star_schedule": (("schedules",), "schedules in the LLM output format (the persistence benchmark "
                                               "and psg-data synth datasets provide them)"),
}
"""Estimator -> (settings of which one must be given or hinted, what that is)."""


def require_hints(specs: list[EstimatorSpec], hints: dict[str, Any], dataset_label: str, *,
                  what: str = "") -> None:
    """Refuse, before any work, estimators that need a setting the dataset cannot provide.

    Raises:
        EvaluationError: ``--estimator 'NAME': NAME needs ...; DATASET has none`` (one line).
    """
    for spec in specs:
        need = NEEDS.get(spec.name)
        if need is None:
            continue
        keys, text = need
        given = dict(spec.settings)
        if not any(given.get(k) is not None or hints.get(k) is not None for k in keys):
            raise EvaluationError(f"--estimator {spec.label!r}: {spec.name} needs {text}; {dataset_label} has none"
                                  + (f" ({what})" if what else ""))
