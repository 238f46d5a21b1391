"""_prefix_products as it was at main aaa7199 (the reference of tests/estimators/test_hmm_scan_equal.py)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def _prefix_products(m: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inclusive prefix products P_t = M_0 @ ... @ M_t of (O, T, S, S) matrices by recursive doubling.

    Each stored product is scaled by its largest entry; the log of the scale is returned (O, T), so
    that products over tens of thousands of steps neither overflow nor underflow.
    """
    n_obj, n_t, n_s, _ = m.shape

    def scale(x: NDArray[np.float64]) -> NDArray[np.float64]:
        flat = x.reshape(x.shape[0], x.shape[1], n_s * n_s)
        mx = flat[:, :, 0].copy()
        for j in range(1, n_s * n_s):  # elementwise: much faster than a reduction over a tiny axis
            np.maximum(mx, flat[:, :, j], out=mx)
        np.maximum(mx, 1e-300, out=mx)
        x /= mx[:, :, None, None]
        return np.log(mx)

    def matmul(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        if n_s > 3:
            return np.matmul(a, b)
        out = np.zeros(a.shape)
        for i in range(n_s):
            for k in range(n_s):
                for j in range(n_s):
                    out[..., i, k] += a[..., i, j] * b[..., j, k]
        return out

    p = m.copy()
    c = scale(p)
    d = 1
    while d < n_t:
        q = matmul(p[:, :-d], p[:, d:])
        cq = scale(q)
        p[:, d:] = q
        c[:, d:] += c[:, :-d].copy() + cq
        d *= 2
    return p, c
