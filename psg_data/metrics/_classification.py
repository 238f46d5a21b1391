"""Persistence metrics: MAE, balanced accuracy and F1, per sample and integrated over time.

Two conventions are offered and named everywhere:

``"sklearn"``
    scikit-learn's definitions. Balanced accuracy is the mean recall over the classes present
    in ``y_true`` (a sequence with one class scores that class's recall, so an always-present
    feature predicted present scores 1.0); F1 is ``2 TP / (2 TP + FP + FN)`` with
    ``zero_division`` returned when the denominator is 0.

``"reference"``
    What the public Perpetua reference computes (and the paper's Table I reports)::

        TPR = TP / (TP + FN + 1e-8)        TNR = TN / (TN + FP + 1e-8)
        B-Acc = (TPR + TNR) / 2
        P = TP / (TP + FP + 1e-8)          R = TPR
        F1 = 2 P R / (P + R + 1e-8)

    so a feature that is always present scores at most 0.5 balanced accuracy (its TNR is 0),
    and F1 is 0 when there is no true positive. Nothing ever divides by zero.

Binarisation: a belief ``b`` counts as *present* (positive class) iff ``b >= threshold``
(default 0.5; a belief of exactly 0.5 is present), as the reference does.

Masking: ground-truth values equal to the privileged codes ``-1`` (missing: receptacle hidden)
and ``-2`` (receptacle invalid for the object) are excluded from every metric; see
:func:`mask_codes`. Any other ground-truth value outside {0, 1} is an error.

Time integration (:func:`time_integrated_mae` and friends): on a ground-truth time grid
``t_0 < t_1 < ... < t_N`` (seconds), each metric's counts are trapezoid integrals over time, e.g.
``MAE = (1 / span) * integral |x(t) - b(t)| dt``. This is exactly the weighted per-sample
metric with trapezoid weights ``w_i = (t_{i+1} - t_{i-1}) / 2`` (halves at the ends), see
:func:`trapezoid_weights`. With masked samples, only intervals whose two end points are both
valid are integrated (the span is the total length of those intervals). With ``windows`` the
integral is bounded by scoring windows (:func:`window_weights`, :mod:`._time_weights`): the gaps
between them (nights nobody scored) get no weight.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EvaluationError
from psg_data.metrics._time_weights import trapezoid_weights, window_weights

__all__ = [
    "PRIVILEGED_CODES",
    "Convention",
    "mask_codes",
    "binarize",
    "trapezoid_weights",
    "window_weights",
    "confusion_counts",
    "mae",
    "balanced_accuracy",
    "f1",
    "time_integrated_mae",
    "time_integrated_balanced_accuracy",
    "time_integrated_f1",
    "span_weighted_mean",
]

PRIVILEGED_CODES: tuple[int, ...] = (-1, -2)
"""Ground-truth codes that are not a state: -1 = missing (receptacle hidden), -2 = invalid pair."""

Convention = Literal["reference", "sklearn"]

_EPS = 1e-8
_CONVENTIONS = ("reference", "sklearn")


def mask_codes(y_true: ArrayLike, codes: Sequence[int] = PRIVILEGED_CODES) -> NDArray[np.bool_]:
    """Boolean mask of the samples to score (True) given ground truth with privileged codes.

    Args:
        y_true: (N,) ground truth, 1 = present, 0 = absent, or one of ``codes``.
        codes: values that mark a sample as not scorable (default -1 missing, -2 invalid).

    Returns:
        (N,) bool, False where ``y_true`` is one of ``codes``.

    Raises:
        EvaluationError: if ``y_true`` holds a value that is neither 0, 1 nor one of ``codes``.

    Example:
        >>> mask_codes([1, 0, -1, -2, 1]).tolist()
        [True, True, False, False, True]
    """
    y = np.asarray(y_true).reshape(-1)
    if y.dtype.kind == "f" and not np.all(np.isfinite(y)):
        raise EvaluationError("y_true contains NaN or inf; expected 0, 1 or a privileged code")
    valid = ~np.isin(y, np.asarray(list(codes)))
    bad = valid & (y != 0) & (y != 1)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise EvaluationError(f"y_true[{i}] = {y[i].item()!r}: expected 0, 1 or one of the codes {tuple(codes)}")
    return valid


def binarize(y_pred: ArrayLike, *, threshold: float = 0.5) -> NDArray[np.int8]:
    """Binarise beliefs: 1 (present) iff ``y_pred >= threshold``.

    Example:
        >>> binarize([0.2, 0.5, 0.9]).tolist()
        [0, 1, 1]
    """
    return (np.asarray(y_pred, dtype=np.float64) >= threshold).astype(np.int8)


def _prepare(
    y_true: ArrayLike,
    y_pred: ArrayLike,
    sample_weight: ArrayLike | None,
    codes: Sequence[int],
) -> tuple[NDArray[np.int8], NDArray[np.float64], NDArray[np.float64]]:
    """Validate, drop masked samples, return (y, b, w)."""
    y = np.asarray(y_true).reshape(-1)
    b = np.asarray(y_pred, dtype=np.float64).reshape(-1)
    if y.shape != b.shape:
        raise EvaluationError(f"y_true and y_pred differ in length ({y.size} vs {b.size})")
    if not np.all(np.isfinite(b)):
        i = int(np.argmax(~np.isfinite(b)))
        raise EvaluationError(f"y_pred[{i}] = {b[i]}: predictions must be finite")
    if sample_weight is None:
        w = np.ones(y.shape, dtype=np.float64)
    else:
        w = np.asarray(sample_weight, dtype=np.float64).reshape(-1)
        if w.shape != y.shape:
            raise EvaluationError(f"sample_weight has {w.size} entries, y_true has {y.size}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise EvaluationError("sample_weight must be finite and non-negative")
    keep = mask_codes(y, codes)
    y, b, w = y[keep].astype(np.int8), b[keep], w[keep]
    if y.size == 0 or not np.sum(w) > 0:
        raise EvaluationError("no samples to score (empty input, all ground truth masked, or all weights 0)")
    return y, b, w


def confusion_counts(
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    sample_weight: ArrayLike | None = None,
    threshold: float = 0.5,
    codes: Sequence[int] = PRIVILEGED_CODES,
) -> tuple[float, float, float, float]:
    """Weighted confusion counts ``(tp, fp, fn, tn)``, positive = present, ``b >= threshold``.

    Example:
        >>> confusion_counts([1, 1, 0, 0], [0.9, 0.2, 0.5, 0.1])
        (1.0, 1.0, 1.0, 1.0)
    """
    y, b, w = _prepare(y_true, y_pred, sample_weight, codes)
    return _counts(y, b, w, threshold)


def _counts(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64],
            threshold: float) -> tuple[float, float, float, float]:
    pos = b >= threshold
    t = y == 1
    tp = float(np.sum(w[t & pos]))
    fp = float(np.sum(w[~t & pos]))
    fn = float(np.sum(w[t & ~pos]))
    tn = float(np.sum(w[~t & ~pos]))
    return tp, fp, fn, tn


def _check_convention(convention: str) -> None:
    if convention not in _CONVENTIONS:
        raise EvaluationError(f"convention must be one of {_CONVENTIONS}, got {convention!r}")


def _mae(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64], threshold: float | None) -> float:
    x = b if threshold is None else (b >= threshold).astype(np.float64)
    return float(np.sum(w * np.abs(y - x)) / np.sum(w))


def _bacc(y: NDArray[np.int8], b: NDArray[np.float64], w: NDArray[np.float64], threshold: float,
          convention: str) -> float:
    return _bacc_of(*_counts(y, b, w, threshold), convention)


def _bacc_of(tp: float, fp: float, fn: float, tn: float, convention: str) -> float:
    """Balanced accuracy from the weighted confusion counts."""
    if convention == "reference":
        return (tp / (tp + fn + _EPS) + tn / (tn + fp + _EPS)) / 2.0
    recalls = []
    if tp + fn > 0:
        recalls.append(tp / (tp + fn))
    if tn + fp > 0:
        recalls.append(tn / (tn + fp))
    return float(np.mean(recalls))


def _f1(
    y: NDArray[np.int8],
    b: NDArray[np.float64],
    w: NDArray[np.float64],
    threshold: float,
    convention: str,
    zero_division: float,
) -> float:
    tp, fp, fn, _ = _counts(y, b, w, threshold)
    return _f1_of(tp, fp, fn, convention, zero_division)


def _f1_of(tp: float, fp: float, fn: float, convention: str, zero_division: float) -> float:
    """F1 of 'present' from the weighted confusion counts."""
    if convention == "reference":
        p = tp / (tp + fp + _EPS)
        r = tp / (tp + fn + _EPS)
        return 2.0 * p * r / (p + r + _EPS)
    den = 2.0 * tp + fp + fn
    return float(zero_division) if den == 0 else 2.0 * tp / den


def mae(
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    sample_weight: ArrayLike | None = None,
    threshold: float | None = None,
    codes: Sequence[int] = PRIVILEGED_CODES,
) -> float:
    """Mean absolute error between ground-truth state and belief.

    Args:
        y_true: (N,) ground truth (1 present, 0 absent; ``codes`` are excluded).
        y_pred: (N,) beliefs P(present) in [0, 1].
        sample_weight: (N,) non-negative weights (default 1).
        threshold: None (default) scores the raw belief, as the reference's MAE does; a number
            scores the binarised belief ``b >= threshold`` (then MAE is the error rate).
        codes: ground-truth values to exclude.

    Returns:
        Weighted mean of ``|y - b|``, in [0, 1] for beliefs in [0, 1].

    Raises:
        EvaluationError: on mismatched lengths, non-finite predictions or nothing left to score.

    Example:
        >>> mae([1, 0, -1], [0.75, 0.5, 0.0])
        0.375
    """
    y, b, w = _prepare(y_true, y_pred, sample_weight, codes)
    return _mae(y, b, w, threshold)


def balanced_accuracy(
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    sample_weight: ArrayLike | None = None,
    threshold: float = 0.5,
    convention: Convention = "sklearn",
    codes: Sequence[int] = PRIVILEGED_CODES,
) -> float:
    """Balanced accuracy of binarised beliefs (present iff ``b >= threshold``).

    Args:
        y_true: (N,) ground truth (1 present, 0 absent; ``codes`` are excluded).
        y_pred: (N,) beliefs in [0, 1] (or 0/1 labels).
        sample_weight: (N,) non-negative weights.
        threshold: binarisation threshold, compared with ``>=``.
        convention: ``"sklearn"`` (default here): mean recall over the classes present in
            ``y_true``, so single-class ground truth scores that class's recall (scikit-learn
            also warns in that case; we do not). ``"reference"``: ``(TPR + TNR) / 2`` with 1e-8
            guards; single-class ground truth scores at most 0.5.
        codes: ground-truth values to exclude.

    Returns:
        Balanced accuracy in [0, 1].

    Example:
        >>> balanced_accuracy([1, 1, 1], [0.9, 0.8, 0.7])
        1.0
        >>> round(balanced_accuracy([1, 1, 1], [0.9, 0.8, 0.7], convention="reference"), 6)
        0.5
    """
    _check_convention(convention)
    y, b, w = _prepare(y_true, y_pred, sample_weight, codes)
    return _bacc(y, b, w, threshold, convention)


def f1(
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    sample_weight: ArrayLike | None = None,
    threshold: float = 0.5,
    convention: Convention = "sklearn",
    zero_division: float = 0.0,
    codes: Sequence[int] = PRIVILEGED_CODES,
) -> float:
    """F1 score of binarised beliefs, positive class = present (``b >= threshold``).

    Args:
        y_true: (N,) ground truth (1 present, 0 absent; ``codes`` are excluded).
        y_pred: (N,) beliefs in [0, 1] (or 0/1 labels).
        sample_weight: (N,) non-negative weights.
        threshold: binarisation threshold, compared with ``>=``.
        convention: ``"sklearn"`` (default here): ``2TP / (2TP + FP + FN)``, and
            ``zero_division`` when there is no positive in truth nor prediction.
            ``"reference"``: ``2PR / (P + R + 1e-8)`` with 1e-8 guards in P and R (0 when there
            is no true positive; ``zero_division`` is ignored).
        zero_division: value for 0/0 in the sklearn convention.
        codes: ground-truth values to exclude.

    Returns:
        F1 in [0, 1].

    Example:
        >>> f1([1, 0, 1, 0], [0.5, 0.4, 0.2, 0.9])
        0.5
    """
    _check_convention(convention)
    y, b, w = _prepare(y_true, y_pred, sample_weight, codes)
    return _f1(y, b, w, threshold, convention, zero_division)


def _time_prepare(
    t_s: ArrayLike, y_true: ArrayLike, y_pred: ArrayLike, codes: Sequence[int], windows: ArrayLike | None = None
) -> tuple[NDArray[np.int8], NDArray[np.float64], NDArray[np.float64]]:
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    y = np.asarray(y_true).reshape(-1)
    b = np.asarray(y_pred, dtype=np.float64).reshape(-1)
    if not (t.shape == y.shape == b.shape):
        raise EvaluationError(f"t_s, y_true and y_pred differ in length ({t.size}, {y.size}, {b.size})")
    if t.size > 1 and np.any(np.diff(t) < 0):
        order = np.argsort(t, kind="stable")
        t, y, b = t[order], y[order], b[order]
    valid = mask_codes(y, codes)
    w = trapezoid_weights(t, valid) if windows is None else window_weights(t, windows, valid)
    if not np.sum(w) > 0:
        raise EvaluationError(
            "time-integrated metric needs at least two distinct valid times (zero integrated span)"
            + ("" if windows is None else " inside the scoring windows")
        )
    return _prepare(y, b, w, codes)


def time_integrated_mae(
    t_s: ArrayLike,
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    threshold: float | None = None,
    codes: Sequence[int] = PRIVILEGED_CODES,
    windows: ArrayLike | None = None,
) -> float:
    """MAE integrated over time: ``(1 / span) * integral |x(t) - b(t)| dt`` (trapezoid rule).

    Args:
        t_s: (N,) ground-truth grid times, seconds (sorted internally if not sorted).
        y_true: (N,) ground truth on the grid (``codes`` excluded, see module docs).
        y_pred: (N,) beliefs at the grid times.
        threshold: None (default, the reference) integrates the raw belief; a number integrates
            the binarised belief.
        codes: ground-truth values to exclude.
        windows: (K, 2) scoring windows ``[start, end]``, seconds: integrate only inside them
            (:func:`~psg_data.metrics.window_weights`); None (default) integrates the whole span
            (the reference's plain trapezoid).

    Returns:
        Time-averaged absolute error in [0, 1] (averaged over the scored time).

    Raises:
        EvaluationError: when the valid span is zero (fewer than two distinct valid times).

    Example:
        >>> time_integrated_mae([0.0, 1.0, 3.0], [1, 1, 0], [1.0, 0.0, 0.0])
        0.5
    """
    y, b, w = _time_prepare(t_s, y_true, y_pred, codes, windows)
    return _mae(y, b, w, threshold)


def time_integrated_balanced_accuracy(
    t_s: ArrayLike,
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    threshold: float = 0.5,
    convention: Convention = "reference",
    codes: Sequence[int] = PRIVILEGED_CODES,
    windows: ArrayLike | None = None,
) -> float:
    """Balanced accuracy with time-integrated (trapezoid) confusion counts (seconds).

    Same definitions as :func:`balanced_accuracy`; the default convention here is
    ``"reference"`` (what the paper's tables use). ``windows`` as in :func:`time_integrated_mae`.

    Example:
        >>> round(time_integrated_balanced_accuracy([0.0, 1.0, 2.0], [1, 1, 1], [1.0, 1.0, 1.0]), 6)
        0.5
    """
    _check_convention(convention)
    y, b, w = _time_prepare(t_s, y_true, y_pred, codes, windows)
    return _bacc(y, b, w, threshold, convention)


def time_integrated_f1(
    t_s: ArrayLike,
    y_true: ArrayLike,
    y_pred: ArrayLike,
    *,
    threshold: float = 0.5,
    convention: Convention = "reference",
    zero_division: float = 0.0,
    codes: Sequence[int] = PRIVILEGED_CODES,
    windows: ArrayLike | None = None,
) -> float:
    """F1 with time-integrated (trapezoid) confusion counts; see :func:`f1`.

    The default convention here is ``"reference"``; ``windows`` as in :func:`time_integrated_mae`.

    Example:
        >>> round(time_integrated_f1([0.0, 1.0, 2.0], [1, 1, 0], [0.9, 0.9, 0.9]), 6)
        0.857143
    """
    _check_convention(convention)
    y, b, w = _time_prepare(t_s, y_true, y_pred, codes, windows)
    return _f1(y, b, w, threshold, convention, zero_division)


def span_weighted_mean(values: ArrayLike, spans: ArrayLike) -> float:
    """Average per-feature scores with weights proportional to their time spans (the reference).

    NaN values (features that could not be scored) are skipped together with their spans.

    Args:
        values: (F,) per-feature metric values.
        spans: (F,) non-negative time spans, seconds (equal spans give the plain mean).

    Returns:
        The weighted mean; NaN if no feature has a value and a positive span.

    Example:
        >>> span_weighted_mean([1.0, 0.0], [3.0, 1.0])
        0.75
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    s = np.asarray(spans, dtype=np.float64).reshape(-1)
    if v.shape != s.shape:
        raise EvaluationError(f"values and spans differ in length ({v.size} vs {s.size})")
    if np.any(s < 0) or not np.all(np.isfinite(s)):
        raise EvaluationError("spans must be finite and non-negative")
    ok = np.isfinite(v) & (s > 0)
    if not np.any(ok):
        return float("nan")
    return float(np.sum(v[ok] * s[ok]) / np.sum(s[ok]))
