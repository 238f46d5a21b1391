"""Navigation metrics: hand-computed fixtures and error paths."""

from __future__ import annotations

import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import abort_rate, distance_travelled, spl, success_rate


def test_success_rate_by_hand():
    assert success_rate([1, 1, 0, 1]) == 0.75
    assert success_rate([True, False], sample_weight=[3.0, 1.0]) == 0.75


def test_spl_by_hand():
    # S * l / max(p, l): 5/10, 2/2, failure -> 0, 0/0 with success -> 1
    assert spl([1, 1, 0, 1], [5.0, 2.0, 3.0, 0.0], [10.0, 2.0, 1.0, 0.0]) == pytest.approx((0.5 + 1 + 0 + 1) / 4)
    # path shorter than the "shortest" path (bad geodesic): capped at 1
    assert spl([1], [4.0], [2.0]) == 1.0
    # 0/0 without success scores 0
    assert spl([0], [0.0], [0.0]) == 0.0
    # weighted: (1 * 0.5 + 3 * 1.0) / 4
    assert spl([1, 1], [1.0, 1.0], [2.0, 1.0], sample_weight=[1.0, 3.0]) == pytest.approx(3.5 / 4)


def test_abort_rate_and_distance_by_hand():
    aborted = [1, 0, 1, 0, 1]
    present = [0, 0, 1, 1, 0]
    assert abort_rate(aborted, target_present=present) == pytest.approx(2 / 3)
    assert abort_rate(aborted) == pytest.approx(3 / 5)
    dist = [3.0, 5.0, 1.0, 1.0, 7.0]
    assert distance_travelled(dist, target_present=present) == pytest.approx(5.0)
    assert distance_travelled(dist, target_present=present, absent_only=False) == pytest.approx(1.0)
    assert distance_travelled(dist) == pytest.approx(17.0 / 5)


def test_navigation_errors():
    with pytest.raises(EvaluationError, match="no episodes"):
        success_rate([])
    with pytest.raises(EvaluationError, match="abort_rate: no episodes"):
        abort_rate([1, 0], target_present=[1, 1])
    with pytest.raises(EvaluationError, match=r"path_m must be finite and >= 0"):
        spl([1], [1.0], [-1.0])
    with pytest.raises(EvaluationError, match="shortest_path_m has 1 entries, expected 2"):
        spl([1, 0], [1.0], [1.0, 2.0])
    with pytest.raises(EvaluationError, match="success must be boolean or 0/1"):
        success_rate([2, 0])
    with pytest.raises(EvaluationError, match="sample_weight has 1 entries"):
        success_rate([1, 0], sample_weight=[1.0])
