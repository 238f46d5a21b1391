"""Object-navigation metrics: success rate, SPL, abort rate and distance travelled.

One entry per episode (query). Lengths are metres. All functions take an optional
``sample_weight`` (scikit-learn's shape) and return a weighted mean over the selected episodes.

- SR: fraction of successful episodes.
- SPL (Anderson et al. 2018, "On Evaluation of Embodied Navigation Agents"):
  ``mean_i S_i * l_i / max(p_i, l_i)`` with ``S_i`` success, ``l_i`` shortest-path length,
  ``p_i`` length of the path taken. The 0/0 case (``l_i = 0`` and ``p_i = 0``, the agent starts
  at the goal and does not move) scores 1 when successful and 0 otherwise.
- AR (correct abort rate): for episodes whose target is absent from the scene, the fraction in
  which the agent aborted (reported that the object is not there).
- Dist: mean distance travelled before the episode terminated (the paper reports it on
  absent-target episodes: pass ``target_present`` to select them).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EvaluationError

__all__ = ["success_rate", "spl", "abort_rate", "distance_travelled"]


def _weights(n: int, sample_weight: ArrayLike | None) -> NDArray[np.float64]:
    if sample_weight is None:
        return np.ones(n, dtype=np.float64)
    w = np.asarray(sample_weight, dtype=np.float64).reshape(-1)
    if w.size != n:
        raise EvaluationError(f"sample_weight has {w.size} entries, expected {n} (one per episode)")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise EvaluationError("sample_weight must be finite and non-negative")
    return w


def _bool(name: str, x: ArrayLike) -> NDArray[np.bool_]:
    a = np.asarray(x).reshape(-1)
    if a.dtype != bool:
        if a.size and not np.all((a == 0) | (a == 1)):
            raise EvaluationError(f"{name} must be boolean or 0/1 per episode")
        a = a.astype(bool)
    return a


def _lengths(name: str, x: ArrayLike, n: int) -> NDArray[np.float64]:
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if a.size != n:
        raise EvaluationError(f"{name} has {a.size} entries, expected {n} (one per episode)")
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise EvaluationError(f"{name} must be finite and >= 0 (metres)")
    return a


def _wmean(values: NDArray[np.float64], w: NDArray[np.float64], what: str) -> float:
    if values.size == 0 or not np.sum(w) > 0:
        raise EvaluationError(f"{what}: no episodes to score (empty input or all weights 0)")
    return float(np.sum(values * w) / np.sum(w))


def _select(target_present: ArrayLike | None, n: int, absent: bool) -> NDArray[np.bool_]:
    if target_present is None:
        return np.ones(n, dtype=bool)
    tp = _bool("target_present", target_present)
    if tp.size != n:
        raise EvaluationError(f"target_present has {tp.size} entries, expected {n}")
    return ~tp if absent else tp


def success_rate(success: ArrayLike, *, sample_weight: ArrayLike | None = None) -> float:
    """Success rate: weighted fraction of successful episodes.

    Args:
        success: (E,) bool or 0/1 per episode.
        sample_weight: (E,) non-negative weights.

    Returns:
        SR in [0, 1].

    Example:
        >>> success_rate([True, False, True, True])
        0.75
    """
    s = _bool("success", success)
    return _wmean(s.astype(np.float64), _weights(s.size, sample_weight), "success_rate")


def spl(
    success: ArrayLike,
    shortest_path_m: ArrayLike,
    path_m: ArrayLike,
    *,
    sample_weight: ArrayLike | None = None,
) -> float:
    """Success weighted by path length (Anderson et al. 2018).

    Args:
        success: (E,) bool or 0/1 per episode.
        shortest_path_m: (E,) geodesic shortest-path length from start to goal, metres.
        path_m: (E,) length of the path the agent took, metres.
        sample_weight: (E,) non-negative weights.

    Returns:
        SPL in [0, 1]. ``l = p = 0`` with success counts 1.

    Example:
        >>> spl([1, 1, 0], [4.0, 0.0, 3.0], [8.0, 0.0, 3.0])
        0.5
    """
    s = _bool("success", success)
    n = s.size
    l_ = _lengths("shortest_path_m", shortest_path_m, n)
    p = _lengths("path_m", path_m, n)
    den = np.maximum(p, l_)
    ratio = np.divide(l_, den, out=np.ones(n, dtype=np.float64), where=den > 0)
    return _wmean(s.astype(np.float64) * ratio, _weights(n, sample_weight), "spl")


def abort_rate(
    aborted: ArrayLike,
    *,
    target_present: ArrayLike | None = None,
    sample_weight: ArrayLike | None = None,
) -> float:
    """Correct abort rate: fraction of absent-target episodes in which the agent aborted.

    Args:
        aborted: (E,) bool or 0/1, the agent declared the target not found and stopped.
        target_present: (E,) bool; when given, only episodes with an absent target are scored
            (otherwise every episode is assumed to have an absent target).
        sample_weight: (E,) non-negative weights.

    Returns:
        AR in [0, 1].

    Raises:
        EvaluationError: if no absent-target episode is selected.

    Example:
        >>> abort_rate([1, 0, 1, 1], target_present=[0, 0, 1, 0])
        0.6666666666666666
    """
    a = _bool("aborted", aborted)
    w = _weights(a.size, sample_weight)
    m = _select(target_present, a.size, absent=True)
    return _wmean(a[m].astype(np.float64), w[m], "abort_rate")


def distance_travelled(
    distance_m: ArrayLike,
    *,
    target_present: ArrayLike | None = None,
    absent_only: bool = True,
    sample_weight: ArrayLike | None = None,
) -> float:
    """Mean distance travelled before termination, metres.

    Args:
        distance_m: (E,) distance travelled per episode, metres.
        target_present: (E,) bool; when given, episodes are selected by it (see ``absent_only``).
        absent_only: with ``target_present``, score only absent-target episodes (the paper's
            Dist column); False scores only present-target episodes.
        sample_weight: (E,) non-negative weights.

    Returns:
        Weighted mean distance, metres.

    Example:
        >>> distance_travelled([2.0, 4.0, 10.0], target_present=[0, 0, 1])
        3.0
    """
    d = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    d = _lengths("distance_m", d, d.size)
    w = _weights(d.size, sample_weight)
    m = _select(target_present, d.size, absent=absent_only)
    return _wmean(d[m], w[m], "distance_travelled")
