"""Navigation metrics: what each argument accepts and which error names which argument (issue 33's mutants)."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import abort_rate, distance_travelled, spl, success_rate

SUCCESS = [1, 1, 0, 1]
SHORTEST = [0.25, 2.0, 3.0, 0.5]
PATH = [0.5, 2.0, 1.0, 0.75]
WEIGHT = [1.0, 3.0, 2.0, 0.0]
PRESENT = [0, 1, 0, 0]


def _by_hand_spl(weight: list[float]) -> float:
    terms = [s * l_ / max(p, l_) for s, l_, p in zip(SUCCESS, SHORTEST, PATH)]
    return float(np.dot(terms, weight) / np.sum(weight))


def test_spl_below_one_metre_and_weighted_by_hand() -> None:
    # lengths under 1 m are divided, not treated as the 0/0 case; a weight-0 episode is ignored
    assert spl(SUCCESS, SHORTEST, PATH) == pytest.approx((0.5 + 1.0 + 0.0 + 0.5 / 0.75) / 4)
    assert spl(SUCCESS, SHORTEST, PATH, sample_weight=WEIGHT) == pytest.approx(_by_hand_spl(WEIGHT))


def test_abort_rate_and_distance_use_the_weights() -> None:
    # absent-target episodes 0, 2, 3 with weights 1, 2, 0: aborted 1, 0, 1 -> 1 / 3
    assert abort_rate(SUCCESS, target_present=PRESENT, sample_weight=WEIGHT) == pytest.approx(1 / 3)
    assert distance_travelled(PATH, target_present=PRESENT, sample_weight=WEIGHT) == pytest.approx((0.5 + 2.0) / 3)
    assert distance_travelled(PATH, sample_weight=WEIGHT) == pytest.approx((0.5 + 6.0 + 2.0) / 6)


def _all_metrics(success, shortest, path, present, weight) -> list[float]:
    return [success_rate(success, sample_weight=weight),
            spl(success, shortest, path, sample_weight=weight),
            abort_rate(success, target_present=present, sample_weight=weight),
            distance_travelled(path, target_present=present, sample_weight=weight)]


@pytest.mark.parametrize("form", ["row", "column", "strings"])
def test_any_array_like_of_one_value_per_episode_is_accepted(form: str) -> None:
    # (1, E) and (E, 1) arrays are flattened; numbers given as text (a CSV column) are parsed
    expected = _all_metrics(SUCCESS, SHORTEST, PATH, PRESENT, WEIGHT)

    def cast(x: list[float], numeric: bool = True):
        if form == "row":
            return np.asarray(x)[None, :]
        if form == "column":
            return np.asarray(x)[:, None]
        return [str(float(v)) for v in x] if numeric else x

    got = _all_metrics(cast(SUCCESS, numeric=False), cast(SHORTEST), cast(PATH), cast(PRESENT, numeric=False),
                       cast(WEIGHT))
    assert got == pytest.approx(expected)


def test_bad_weights_each_raise() -> None:
    for bad in ([1.0, -1.0], [1.0, np.inf], [np.nan, 1.0]):
        with pytest.raises(EvaluationError, match=r"^sample_weight must be finite and non-negative$"):
            success_rate([1, 0], sample_weight=bad)
    assert success_rate([1, 0], sample_weight=[0.0, 1.0]) == 0.0  # zero is a valid weight


@pytest.mark.parametrize(("call", "message"), [
    (lambda: success_rate([2, 0]), r"^success must be boolean or 0/1 per episode$"),
    (lambda: spl([2], [1.0], [1.0]), r"^success must be boolean or 0/1 per episode$"),
    (lambda: abort_rate([2]), r"^aborted must be boolean or 0/1 per episode$"),
    (lambda: abort_rate([1], target_present=[3]), r"^target_present must be boolean or 0/1 per episode$"),
    (lambda: abort_rate([1, 0], target_present=[1]), r"^target_present has 1 entries, expected 2$"),
    (lambda: spl([1], [1.0], [1.0, 2.0]), r"^path_m has 2 entries, expected 1 \(one per episode\)$"),
    (lambda: spl([1], [-1.0], [1.0]), r"^shortest_path_m must be finite and >= 0 \(metres\)$"),
    (lambda: distance_travelled([np.inf]), r"^distance_m must be finite and >= 0 \(metres\)$"),
    (lambda: success_rate([1], sample_weight=[1.0, 1.0]),
     r"^sample_weight has 2 entries, expected 1 \(one per episode\)$"),
    (lambda: success_rate([0], sample_weight=[0.0]),
     r"^success_rate: no episodes to score \(empty input or all weights 0\)$"),
    (lambda: spl([], [], []), r"^spl: no episodes to score"),
    (lambda: abort_rate([1], target_present=[1]), r"^abort_rate: no episodes to score"),
    (lambda: distance_travelled([1.0], target_present=[1]), r"^distance_travelled: no episodes to score"),
])
def test_each_error_names_its_argument(call, message: str) -> None:
    with pytest.raises(EvaluationError, match=message):
        call()
