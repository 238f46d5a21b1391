"""Per-sample metrics (MAE, balanced accuracy, F1): array-likes, codes and each error message (issue 33)."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import balanced_accuracy, f1, mae

Y = [1, 0, 1, -1, 0, 1]
B = [0.9, 0.6, 0.2, 0.5, 0.4, 0.7]
W = [1.0, 2.0, 0.5, 1.0, 3.0, 1.0]


def _all(y, b, w, **kw) -> list[float]:
    return [mae(y, b, sample_weight=w, **kw), mae(y, b, sample_weight=w, threshold=0.5, **kw),
            balanced_accuracy(y, b, sample_weight=w, **kw), f1(y, b, sample_weight=w, **kw),
            balanced_accuracy(y, b, sample_weight=w, convention="reference", **kw),
            f1(y, b, sample_weight=w, convention="reference", **kw)]


@pytest.mark.parametrize("form", ["row", "column", "strings"])
def test_any_array_like_of_one_value_per_sample_is_accepted(form: str) -> None:
    expected = _all(Y, B, W)
    if form == "strings":  # numbers as text (a CSV column)
        got = _all(Y, [str(v) for v in B], [str(v) for v in W])
    else:
        cast = (lambda x: np.asarray(x)[None, :]) if form == "row" else (lambda x: np.asarray(x)[:, None])
        got = _all(cast(Y), cast(B), cast(W))
    assert got == pytest.approx(expected)


def test_custom_codes_replace_the_privileged_ones() -> None:
    y = [1, 9, 0, 1]
    assert mae(y, [0.5, 0.0, 0.5, 1.0], codes=(9,)) == pytest.approx(1 / 3)
    with pytest.raises(EvaluationError, match=r"y_true\[1\] = -1"):
        mae([1, -1], [0.5, 0.5], codes=(9,))


@pytest.mark.parametrize(("call", "message"), [
    (lambda: mae([1, 0], [0.5, np.inf]), r"^y_pred\[1\] = inf: predictions must be finite$"),
    (lambda: mae([1, 0, 1], [0.5, 0.5, np.nan]), r"^y_pred\[2\] = nan: predictions must be finite$"),
    (lambda: mae([1, 0], [0.5, 0.5], sample_weight=[1.0]), r"^sample_weight has 1 entries, y_true has 2$"),
    (lambda: f1([1, 0], [0.5, 0.5], sample_weight=[1.0, -1.0]), r"^sample_weight must be finite and non-negative$"),
    (lambda: f1([1, 0], [0.5, 0.5], sample_weight=[1.0, np.nan]), r"^sample_weight must be finite and non-negative$"),
    (lambda: mae([1, 0], [0.5, 0.5], sample_weight=[0.0, 0.0]),
     r"^no samples to score \(empty input, all ground truth masked, or all weights 0\)$"),
    (lambda: balanced_accuracy([-1], [0.5]),
     r"^no samples to score \(empty input, all ground truth masked, or all weights 0\)$"),
    (lambda: mae([1, np.nan], [0.5, 0.5]), r"^y_true contains NaN or inf; expected 0, 1 or a privileged code$"),
])
def test_each_error_names_its_argument(call, message: str) -> None:
    with pytest.raises(EvaluationError, match=message):
        call()
