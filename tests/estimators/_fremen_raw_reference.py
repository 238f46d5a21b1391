"""``FremenComponents.raw`` as main 97528cb computed it (one component after the other), kept as the
reference of tests/estimators/test_est_prior_logit_memo.py."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.estimators._fremen import FremenComponents


def reference_raw(c: FremenComponents, tau: ArrayLike) -> NDArray[np.float64]:
    tau = np.asarray(tau, dtype=np.float64)
    out = np.full(tau.shape, c.mean, dtype=np.float64)
    if c.k.size:
        theta = np.mod(tau, c.base_period_s) * (2 * np.pi / c.base_period_s)
        amp = 2 * np.abs(c.coef)
        ph = np.angle(c.coef)
        for kk, a, p in zip(c.k, amp, ph):
            out += a * np.cos(kk * theta + p)
    return out
