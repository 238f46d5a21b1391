"""Time weights that turn a weighted mean into a time integral: plain trapezoid, or bounded by scoring windows.

Both weightings integrate the piecewise-linear interpolant of the per-sample values between
consecutive sample times (the trapezoid rule, which the Perpetua reference uses):

``trapezoid_weights(t)``  (the reference; ``weighting="reference"``)
    ``w_i = (t_{i+1} - t_{i-1}) / 2`` (halves at the ends): every gap between two samples is
    integrated, also a night or a weekend nobody scored.

``window_weights(t, windows)``  (gap-aware; ``weighting="windows"``)
    The same interpolant integrated only over the parts of ``[t_0, t_N]`` that lie inside the
    scoring windows (e.g. a lab's operating hours 9:00-17:00 local): for an interval
    ``[t_i, t_{i+1}]`` of length ``D`` and its overlap ``[u, v]`` with a window,
    ``w_i += integral_u^v (t_{i+1} - t) / D dt`` and ``w_{i+1} += integral_u^v (t - t_i) / D dt``.
    ``sum(w)`` is the scored time inside the windows, seconds. With one window covering
    ``[t_0, t_N]`` the weights equal :func:`trapezoid_weights`.

Only intervals whose two end points are valid (``valid`` mask, e.g. ground truth not masked) are
integrated, as in the reference.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EvaluationError

__all__ = ["trapezoid_weights", "window_weights", "check_windows"]


def _times_and_mask(t_s: ArrayLike, valid: ArrayLike | None) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    v = np.ones(t.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool).reshape(-1)
    if v.shape != t.shape:
        raise EvaluationError(f"valid mask has {v.size} entries, t_s has {t.size}")
    if not np.all(np.isfinite(t)):
        raise EvaluationError("t_s contains NaN or inf")
    if t.size > 1 and np.any(np.diff(t) < 0):
        i = int(np.argmax(np.diff(t) < 0)) + 1
        raise EvaluationError(f"t_s must be non-decreasing, got {t[i]} after {t[i - 1]} at index {i}")
    return t, v


def trapezoid_weights(t_s: ArrayLike, valid: ArrayLike | None = None) -> NDArray[np.float64]:
    """Per-sample weights that turn a weighted mean into a trapezoid time integral over the span.

    For sorted times ``t`` the weight of sample ``i`` is half the length of each adjacent interval
    whose two end points are valid; ``sum(w)`` is the integrated span (seconds).

    Args:
        t_s: (N,) non-decreasing times, seconds.
        valid: (N,) bool mask of usable samples (default: all).

    Returns:
        (N,) float64 weights, seconds.

    Example:
        >>> trapezoid_weights([0.0, 1.0, 3.0]).tolist()
        [0.5, 1.5, 1.0]
    """
    t, v = _times_and_mask(t_s, valid)
    w = np.zeros(t.shape, dtype=np.float64)
    if t.size < 2:
        return w
    dt = np.diff(t) * (v[:-1] & v[1:])
    w[:-1] += dt / 2.0
    w[1:] += dt / 2.0
    return w


def check_windows(windows: ArrayLike) -> NDArray[np.float64]:
    """Validate scoring windows: a (K, 2) array of ``[start, end)`` seconds, sorted and disjoint.

    Raises:
        EvaluationError: wrong shape, non-finite, empty or reversed windows, or overlaps.

    Example:
        >>> check_windows([[0, 8], [24, 32]]).tolist()
        [[0.0, 8.0], [24.0, 32.0]]
    """
    w = np.asarray(windows, dtype=np.float64)
    if w.size == 0:
        return np.zeros((0, 2), dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 2:
        raise EvaluationError(f"windows: expected a (K, 2) array of [start, end] seconds, got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise EvaluationError("windows: start and end must be finite seconds")
    if np.any(w[:, 1] <= w[:, 0]):
        k = int(np.argmax(w[:, 1] <= w[:, 0]))
        raise EvaluationError(f"windows[{k}] = [{w[k, 0]}, {w[k, 1]}]: end must be after start")
    if w.shape[0] > 1 and np.any(w[1:, 0] < w[:-1, 1]):
        k = int(np.argmax(w[1:, 0] < w[:-1, 1])) + 1
        raise EvaluationError(f"windows[{k}] starts at {w[k, 0]} before windows[{k - 1}] ends ({w[k - 1, 1]}); "
                              "expected sorted, disjoint windows")
    return w


def _window_moments(x: NDArray[np.float64], w: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(G(x), H(x)): the length of ``windows ∩ (-inf, x]`` and the integral of ``t`` over it."""
    a, b = w[:, 0], w[:, 1]
    full_len = np.concatenate([[0.0], np.cumsum(b - a)])
    full_mom = np.concatenate([[0.0], np.cumsum((b * b - a * a) / 2.0)])
    k = np.searchsorted(a, x, side="right")  # windows starting at or before x
    g = full_len[np.maximum(k - 1, 0)].copy()
    h = full_mom[np.maximum(k - 1, 0)].copy()
    inside = k > 0
    kk = np.maximum(k - 1, 0)
    end = np.minimum(x, b[kk])
    part = inside & (end > a[kk])
    g[part] += end[part] - a[kk][part]
    h[part] += (end[part] ** 2 - a[kk][part] ** 2) / 2.0
    g[~inside] = 0.0
    h[~inside] = 0.0
    return g, h


def window_weights(t_s: ArrayLike, windows: ArrayLike, valid: ArrayLike | None = None) -> NDArray[np.float64]:
    """Trapezoid weights restricted to scoring windows (module docstring): gaps outside them get no weight.

    Args:
        t_s: (N,) non-decreasing sample times, seconds.
        windows: (K, 2) sorted, disjoint ``[start, end]`` windows, seconds (same clock as ``t_s``).
        valid: (N,) bool mask of usable samples (default: all).

    Returns:
        (N,) float64 weights, seconds; ``sum`` = the valid time inside the windows.

    Example:
        >>> window_weights([0.0, 2.0, 4.0], [[0.0, 1.0], [3.0, 4.0]]).tolist()
        [0.75, 0.5, 0.75]
    """
    t, v = _times_and_mask(t_s, valid)
    win = check_windows(windows)
    w = np.zeros(t.shape, dtype=np.float64)
    if t.size < 2 or win.shape[0] == 0:
        return w
    origin = t[0]  # shift the clock: squares of epoch seconds lose precision
    ts, ws = t - origin, win - origin
    g, h = _window_moments(ts, ws)
    dt = np.diff(ts)
    use = (v[:-1] & v[1:]) & (dt > 0)
    dg, dh = np.diff(g), np.diff(h)
    safe = np.where(use, dt, 1.0)
    left = np.where(use, (ts[1:] * dg - dh) / safe, 0.0)
    right = np.where(use, (dh - ts[:-1] * dg) / safe, 0.0)
    w[:-1] += np.clip(left, 0.0, None)
    w[1:] += np.clip(right, 0.0, None)
    return w
