"""The binarisation boundary: a belief of exactly the threshold counts as present (``b >= threshold``)."""

from __future__ import annotations

import pytest

from psg_data.metrics import balanced_accuracy, binarize, f1, mae, time_integrated_mae


def test_a_belief_at_the_threshold_is_present_in_every_thresholded_metric() -> None:
    assert binarize([0.5, 0.4999999], threshold=0.5).tolist() == [1, 0]
    # truth present, belief exactly 0.5: binarised to present -> no error (b > 0.5 would give 1.0)
    assert mae([1], [0.5], threshold=0.5) == 0.0
    assert mae([0], [0.5], threshold=0.5) == 1.0
    assert mae([1, 0], [0.3, 0.3], threshold=0.3) == 0.5
    assert time_integrated_mae([0.0, 1.0], [1, 1], [0.5, 0.5], threshold=0.5) == 0.0
    assert f1([1, 0], [0.5, 0.2]) == pytest.approx(1.0, abs=1e-6)
    assert balanced_accuracy([1, 0], [0.5, 0.2]) == pytest.approx(1.0, abs=1e-6)
