"""Binarisation and the span-weighted mean: what they accept and what they refuse (issue 33's mutants)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import binarize, span_weighted_mean


def test_low_precision_beliefs_are_compared_exactly_with_the_threshold() -> None:
    # float16(0.1) = 0.0999755859375 < 0.1: comparing in float16 would round the threshold to it
    b = np.float16([0.1, 0.2])
    assert binarize(b, threshold=0.1).tolist() == [0, 1]


def test_span_weighted_mean_by_hand_with_spans_below_one_and_zero() -> None:
    assert span_weighted_mean([1.0, 0.0, 0.5], [0.25, 0.75, 0.0]) == pytest.approx(0.25)
    assert span_weighted_mean([1.0, np.nan], [1.0, 5.0]) == 1.0


def test_span_weighted_mean_of_zero_spans_is_nan_without_warning() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert math.isnan(span_weighted_mean([1.0, 0.5], [0.0, 0.0]))


@pytest.mark.parametrize("form", ["row", "column", "strings"])
def test_span_weighted_mean_accepts_any_array_like(form: str) -> None:
    values, spans = [1.0, 0.0, 0.5], [3.0, 1.0, 4.0]
    cast = {"row": lambda x: np.asarray(x)[None, :], "column": lambda x: np.asarray(x)[:, None],
            "strings": lambda x: [str(v) for v in x]}[form]
    expected = (3.0 + 2.0) / 8.0
    assert span_weighted_mean(cast(values), spans) == pytest.approx(expected)
    assert span_weighted_mean(values, cast(spans)) == pytest.approx(expected)


@pytest.mark.parametrize(("values", "spans", "message"), [
    ([1.0], [1.0, 2.0], r"^values and spans differ in length \(1 vs 2\)$"),
    ([1.0], [-1.0], r"^spans must be finite and non-negative$"),
    ([1.0], [np.inf], r"^spans must be finite and non-negative$"),
])
def test_span_weighted_mean_refuses(values: list[float], spans: list[float], message: str) -> None:
    with pytest.raises(EvaluationError, match=message):
        span_weighted_mean(values, spans)
