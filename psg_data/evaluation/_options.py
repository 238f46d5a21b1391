"""Settings of the persistence task in one frozen record (the CLI and the library share its defaults).

:class:`PersistenceOptions` holds every setting of :func:`~psg_data.evaluation.run_persistence_task`
besides the estimators and the data. Three fields default to ``"auto"`` and are decided by the task
(:meth:`PersistenceOptions.resolve`), i.e. by the dataset, never by which estimator wins:

``horizon``
    Adaptive setting only: a prediction at ``t`` uses the observations up to ``t - horizon``.
    ``auto`` = the task's default: one scan interval of a scanned dataset (on the built-in lab
    every scan reveals its step's state, so with a zero horizon ``last_seen`` is nearly exact and
    the score says little), 0 for the persistence benchmark (the paper's adaptive protocol) and
    for bare streams.
``weighting`` / ``windows``
    ``windows``: time integrals bounded by the scoring windows (the dataset's operating hours,
    :func:`~psg_data.evaluation.dataset_windows`); ``reference``: the plain trapezoid over the whole
    span (the Perpetua reference, used by the Sec. V-A benchmark so that Table I reproduces).
    ``auto`` = the task's protocol (``reference`` for the benchmark and for bare streams without
    windows, ``windows`` for datasets). ``windows`` may be given as text (``"9-17"``) or a
    :class:`~psg_data.evaluation.DailyWindows`.
``seeds``
    ``auto`` = seed 0 for estimators whose fit does not depend on the seed
    (``fit_depends_on_seed``), seeds 0-2 for those whose fit does (averaged before the
    interval); a tuple gives every seed-dependent estimator those seeds (the others are fitted
    once, with the first).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from psg_data.errors import EvaluationError
from psg_data.evaluation._windows import DailyWindows, format_duration, parse_duration, parse_windows
from psg_data.metrics._classification import PRIVILEGED_CODES

__all__ = ["PersistenceOptions", "SETTINGS", "WEIGHTINGS", "EVAL_TIMES", "AUTO_SEEDS"]

SETTINGS = ("adaptive", "predictive")
WEIGHTINGS = ("auto", "windows", "reference")
EVAL_TIMES = ("observations+grid", "grid", "observations")
AUTO_SEEDS = (0, 1, 2)
"""Seeds of a seed-dependent estimator under ``seeds="auto"``."""


@dataclass(frozen=True)
class PersistenceOptions:
    """All settings of a persistence evaluation (module docstring for the ``auto`` fields).

    Attributes:
        setting: ``adaptive`` (test observations update the filters online, up to ``t - horizon``)
            or ``predictive`` (no test observation is applied).
        horizon: forecast horizon of the adaptive setting, seconds, text (``"2h"``, ``"1d"``) or
            ``"auto"``.
        weighting: ``auto``, ``windows`` or ``reference``.
        windows: ``auto`` (the task's), text such as ``"9-17"`` (local hours) or DailyWindows.
        eval_times: ``observations+grid`` (default), ``grid`` or ``observations``.
        history: ``train`` or ``train+val``: observations applied before the test window.
        seeds: ``auto`` or a tuple of estimator seeds.
        threshold: present iff ``belief >= threshold``.
        convention: convention of the time-integrated metrics (``reference``: the paper's).
        sample_convention: convention of the per-sample metrics.
        codes: ground-truth codes excluded from scoring.
        confidence: nominal coverage of the intervals.
        n_bootstrap: bootstrap resamples (within one dataset).
        bootstrap_seed: seed of the bootstrap.
    """

    setting: str = "adaptive"
    horizon: float | str = "auto"
    weighting: str = "auto"
    windows: DailyWindows | str = "auto"
    eval_times: str = "observations+grid"
    history: str = "train"
    seeds: tuple[int, ...] | str = "auto"
    threshold: float = 0.5
    convention: str = "reference"
    sample_convention: str = "sklearn"
    codes: tuple[int, ...] = PRIVILEGED_CODES
    confidence: float = 0.95
    n_bootstrap: int = 2000
    bootstrap_seed: int = 0

    def __post_init__(self) -> None:
        _one_of("setting", self.setting, SETTINGS)
        _one_of("weighting", self.weighting, WEIGHTINGS)
        _one_of("eval_times", self.eval_times, EVAL_TIMES)
        _one_of("history", self.history, ("train", "train+val"))
        _one_of("convention", self.convention, ("reference", "sklearn"))
        _one_of("sample_convention", self.sample_convention, ("reference", "sklearn"))
        if self.horizon != "auto":
            object.__setattr__(self, "horizon", parse_duration(self.horizon))
        if self.seeds != "auto":
            seeds = tuple(int(s) for s in self.seeds)  # type: ignore[union-attr]
            if not seeds:
                raise EvaluationError("seeds is empty; pass at least one seed, e.g. seeds=(0,), or 'auto'")
            if len(set(seeds)) != len(seeds):
                raise EvaluationError(f"seeds must be distinct, got {list(seeds)}")
            object.__setattr__(self, "seeds", seeds)
        if not 0.0 < float(self.confidence) < 1.0:
            raise EvaluationError(f"confidence must be in (0, 1), got {self.confidence}")
        if int(self.n_bootstrap) < 1:
            raise EvaluationError(f"n_bootstrap must be >= 1, got {self.n_bootstrap}")
        object.__setattr__(self, "codes", tuple(int(c) for c in self.codes))

    @classmethod
    def fields(cls) -> list[str]:
        """The names of the options."""
        return [f.name for f in fields(cls)]

    def replace(self, **changes: Any) -> PersistenceOptions:
        """A copy with ``changes`` applied; unknown names raise :class:`EvaluationError`."""
        bad = sorted(set(changes) - set(self.fields()))
        if bad:
            raise EvaluationError(f"persistence options: unknown settings {bad}; valid: {', '.join(self.fields())}")
        return replace(self, **changes)

    def resolve(self, task: Any) -> PersistenceOptions:
        """These options with every ``auto`` decided by ``task`` (a :class:`PersistenceTask`)."""
        protocol = dict(getattr(task, "protocol", {}) or {})
        windows: DailyWindows | None
        if isinstance(self.windows, DailyWindows):
            windows = self.windows
        elif self.windows == "auto":
            windows = getattr(task, "windows", None)
        else:
            windows = parse_windows(str(self.windows), task.timezone)
        weighting = self.weighting
        if weighting == "auto":
            weighting = protocol.get("weighting") or ("windows" if windows is not None else "reference")
        if weighting == "windows" and windows is None:
            raise EvaluationError(f"{task.name}: weighting 'windows' needs scoring windows; the task has none "
                                  "(give them, e.g. windows='9-17', or use weighting='reference')")
        horizon = self.horizon
        if horizon == "auto":
            horizon = float(protocol.get("horizon_s", getattr(task, "cadence_s", None) or 0.0))
        kept: DailyWindows | str = windows if weighting == "windows" and windows is not None else "none"
        return replace(self, horizon=float(horizon), weighting=weighting, windows=kept)

    @property
    def windows_or_none(self) -> DailyWindows | None:
        """The scoring windows, or None when scores integrate the plain trapezoid."""
        return self.windows if isinstance(self.windows, DailyWindows) else None

    def describe_setting(self) -> str:
        """E.g. ``adaptive, horizon 2 h`` / ``predictive``."""
        if self.setting == "predictive":
            return "predictive"
        h = self.horizon
        return "adaptive" if h in (0, 0.0) else f"adaptive, horizon {format_duration(float(h))}"  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        d = asdict(self)
        d["windows"] = self.windows.to_dict() if isinstance(self.windows, DailyWindows) else self.windows
        d["seeds"] = list(self.seeds) if isinstance(self.seeds, tuple) else self.seeds
        d["codes"] = list(self.codes)
        return d


def _one_of(name: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise EvaluationError(f"{name} must be one of {', '.join(repr(a) for a in allowed)}, got {value!r}")
