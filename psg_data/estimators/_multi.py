"""Multi-receptacle belief of one object (paper eqs. 15-16)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeFilter

__all__ = ["receptacle_belief", "map_receptacle", "joint_log_belief"]


def receptacle_belief(filters: Mapping[str, EdgeFilter], t_s: ArrayLike) -> dict[str, NDArray[np.float64]]:
    """p(x_t^{j,k} | Y^k) for every receptacle k of one object (the factors of eq. 15).

    Args:
        filters: receptacle id -> the filter of edge (object, receptacle).
        t_s: query time(s), Unix seconds.
    """
    return {k: np.asarray(f.predict(t_s), dtype=np.float64) for k, f in filters.items()}


def joint_log_belief(beliefs: Mapping[str, Any], states: Mapping[str, int]) -> NDArray[np.float64]:
    """Log p(x^{j,1..K} = states) = sum_k log p(x^k = states[k]) under the factorisation of eq. 15."""
    out: NDArray[np.float64] | float = 0.0
    for k, b in beliefs.items():
        p = np.clip(np.asarray(b, dtype=np.float64), 0.0, 1.0)
        with np.errstate(divide="ignore"):
            out = out + (np.log(p) if states.get(k, 0) else np.log1p(-p))
    return np.asarray(out)


def map_receptacle(beliefs: Mapping[str, Any], delta: float = 0.2) -> str | None:
    """The MAP receptacle (eq. 16), or None when its belief is below ``delta`` (object absent).

    Among configurations with the object at exactly one receptacle, the joint of eq. 15 is
    p_k * prod_{i != k} (1 - p_i), maximised by the receptacle with the largest belief p_k; the
    object is reported absent when that belief is below ``delta`` (default 0.2, the paper's tool).

    Args:
        beliefs: receptacle id -> scalar belief in [0, 1].
        delta: absence threshold.
    """
    if not beliefs:
        return None
    if not (0.0 <= delta <= 1.0):
        raise EstimatorError(f"map_receptacle: delta must be in [0, 1], got {delta}")
    names = list(beliefs)
    p = np.array([float(np.asarray(beliefs[k]).reshape(-1)[0]) for k in names])
    best = int(np.argmax(p))
    return names[best] if p[best] >= delta else None
