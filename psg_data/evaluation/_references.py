"""Reference rows: every default table shows the best achievable, simple baselines and chance.

Persistence (``psg-eval``, unless ``--no-references``):

- **ceiling** ``process_oracle``: the exact Bayes posterior of the dataset's stored generator model
  (synthetic labs), and ``process_oracle:output=median``, its 0/1 median (the Bayes decision for
  MAE); on a dataset without a generator model the ceiling is ``ground_truth``: the truth itself;
  on a dataset with a test-time shift (the procedural houses) also ``process_oracle:model=train``,
  the posterior under the training model only (the ceiling of a predictor that does not adapt);
- **baselines** ``last_seen`` (the last observation) and ``time_of_week_frequency`` (the training
  share of present observations in the same hour of the week);
- **chance** ``always_absent`` (belief 0: B-Acc 0.5, as for any constant belief; F1 0).

Navigation: the ``oracle`` (the physical state at the query time), ``process_oracle`` when the
dataset has its generator model (the best a predictor can do from the map), ``last_seen_map`` (the
last map state, ConceptGraphs-like), ``time_of_week_frequency`` and ``random_receptacle`` (a
random order of the object's known receptacles: chance). Doors: ``oracle`` (the true door
states), ``all_open`` (every door assumed open), ``last_seen`` (each door's last observation),
``time_of_week_frequency``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from psg_data.evaluation._hints import EstimatorSpec

__all__ = ["Reference", "PAPER_METHODS", "persistence_references", "navigation_references", "door_references",
           "describe_method"]

PAPER_METHODS = ("perpetua_star", "perpetua", "fremen")
"""The paper's methods (its own, Perpetua*, and its comparisons), scored next to the user's estimators by default."""


@dataclass(frozen=True)
class Reference:
    """A reference row: the estimator (a registry spec, or a built-in name), its role and what it is."""

    spec: EstimatorSpec
    role: str
    description: str

    @property
    def label(self) -> str:
        """The row label in tables."""
        return self.spec.label


_DESCRIPTIONS = {
    "process_oracle": "exact Bayes posterior of the dataset's stored generator model (the best achievable)",
    "process_oracle:output=median": "0/1 median of that posterior: the Bayes decision for MAE",
    "process_oracle:model=train": "exact posterior under the training model only (the test-week shift unknown): "
                                  "the best a predictor that does not adapt can do",
    "ground_truth": "the ground truth itself (no generator model stored: the best achievable is perfect)",
    "last_seen": "the edge's last observation (0.5 before any)",
    "time_of_week_frequency": "training share of present observations in the same local hour of the week",
    "always_absent": "belief 0 everywhere: chance (any constant belief scores B-Acc 0.5)",
    "always_present": "belief 1 everywhere",
    "oracle": "the true receptacle at the query time (physical state): the best achievable",
    "last_seen_map": "the last map state (ConceptGraphs-like): never looks where an object moved",
    "random_receptacle": "a random order of the object's known receptacles, random beliefs (chance)",
    "all_open": "plans as if every door were open",
    "perpetua_star": "Perpetua* (the paper's method)",
    "perpetua": "Perpetua (the paper's predecessor)",
    "fremen": "FreMEn (frequency map enhancement)",
    "persistence_filter": "the Persistence Filter (Rosen et al.)",
}


def describe_method(label: str) -> str:
    """One line saying what a row is (its registry description when it is not a reference)."""
    if label in _DESCRIPTIONS:
        return _DESCRIPTIONS[label]
    name = label.split(":", 1)[0].split(" [", 1)[0]
    return _DESCRIPTIONS.get(name, "")


def _ref(name: str, role: str, **settings: Any) -> Reference:
    spec = EstimatorSpec.of(name, **settings)
    return Reference(spec, role, describe_method(spec.label))


def persistence_references(hints: dict[str, Any]) -> list[Reference]:
    """The persistence task's reference rows for a dataset with these estimator hints."""
    if hints.get("dataset") is not None or hints.get("process") is not None:
        ceiling = [_ref("process_oracle", "ceiling"), _ref("process_oracle", "ceiling", output="median")]
        if hints.get("test_shift"):
            ceiling.append(_ref("process_oracle", "ceiling", model="train"))
    else:
        ceiling = [_ref("ground_truth", "ceiling")]
    return [*ceiling, _ref("last_seen", "baseline"), _ref("time_of_week_frequency", "baseline"),
            _ref("always_absent", "chance")]


def navigation_references(hints: dict[str, Any]) -> list[Reference]:
    """Navigation's reference rows (``oracle``, ``last_seen_map`` and ``random_receptacle`` are built into
    the harness; the others are registry estimators).
    """
    out = [_ref("oracle", "ceiling")]
    if hints.get("dataset") is not None or hints.get("process") is not None:
        out.append(Reference(EstimatorSpec.of("process_oracle"), "ceiling",
                             "exact posterior of the stored generator model: the best a predictor can do from the map"))
    return out + [_ref("last_seen_map", "baseline"), _ref("time_of_week_frequency", "baseline"),
                  _ref("random_receptacle", "chance")]


def door_references() -> list[Reference]:
    """The door task's reference rows (``oracle`` and ``all_open`` are built into the door harness)."""
    return [Reference(EstimatorSpec.of("oracle"), "ceiling", "the true door states at the query time"),
            _ref("all_open", "baseline"),
            Reference(EstimatorSpec.of("last_seen"), "baseline", "each door's last observation"),
            Reference(EstimatorSpec.of("time_of_week_frequency"), "baseline",
                      "training share of open observations in the same local hour of the week")]
