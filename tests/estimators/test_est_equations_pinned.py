"""Perpetua*'s eq. 13-14 evaluated by hand at times between the last observation and the prior.

The annealing term alpha(t) = exp(-alpha0 (t - t_N)) is checked at several elapsed times where it is
neither ~1 nor ~0, so a change of its rate (e.g. 2 alpha0) or of its reference time fails here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from psg_data.estimators import ConstantPrior, SurvivalMixture
from psg_data.estimators._perpetua_star import PerpetuaStarFilter

PER = SurvivalMixture("lognormal", np.array([0.5, 0.5]), np.log([3600.0, 8 * 3600.0]), np.array([0.3, 0.5]))
EMG = SurvivalMixture.lognormal_median(4 * 3600.0, 0.6)
ALPHA0 = math.log(2) / 3600.0  # alpha halves every hour


def _fitted(anneal: bool, prior: float = 0.8) -> PerpetuaStarFilter:
    f = PerpetuaStarFilter(("o", "r"), PER, EMG, 0.1, 0.1, ConstantPrior(prior), gamma=0.99, alpha0_per_s=ALPHA0,
                           prior_floor=1e-3, anneal_prediction=anneal)
    t = 1.7e9 + np.arange(12) * 600.0
    y = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0], dtype=np.int8)  # a departure: the evidences differ
    f.update_many(t, y)
    return f


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


@pytest.mark.parametrize("dt_h", [0.0, 0.5, 1.0, 2.0, 3.0])
def test_model_posterior_is_eq13_with_alpha_exp_minus_alpha0_dt(dt_h: float) -> None:
    f = _fitted(anneal=False)
    t_n = float(f._last_t)  # the last observation time t_N
    L_per, L_emg = (float(v) for v in f.L)
    assert abs(L_emg - L_per) > 1.0  # the data favour one model: alpha's value matters
    alpha = math.exp(-ALPHA0 * dt_h * 3600.0)  # 1, 0.71, 0.5, 0.25, 0.125
    want = 1.0 / (1.0 + math.exp(-(alpha * (L_emg - L_per) + _logit(0.8))))
    got = float(f.model_posterior(np.array([t_n + dt_h * 3600.0]))[0])
    assert got == pytest.approx(want, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("anneal", [False, True])
@pytest.mark.parametrize("dt_h", [0.5, 1.0, 3.0])
def test_prediction_is_eq14_and_the_annealed_mixture(anneal: bool, dt_h: float) -> None:
    f = _fitted(anneal=anneal)
    t = np.array([float(f._last_t) + dt_h * 3600.0])
    w = float(f.model_posterior(t)[0])
    p14 = w * float(f.emg.predict(t)[0]) + (1.0 - w) * float(f.per.predict(t)[0])
    if anneal:
        alpha = math.exp(-ALPHA0 * dt_h * 3600.0)
        want = alpha * p14 + (1.0 - alpha) * 0.8
    else:
        want = p14
    assert float(f.predict(t)[0]) == pytest.approx(want, rel=1e-12, abs=1e-15)
