"""Training: EM + AIC for log-normal mixtures, PELT segmentation, error-rate estimates."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EstimatorError
from psg_data.estimators import fit_lognormal_mixture, segment_stream
from psg_data.estimators._training import estimate_error_rates, runs_from_ground_truth, runs_from_segments


def test_em_matches_scikit_learn_likelihood_and_aic_picks_two() -> None:
    from sklearn.mixture import GaussianMixture

    rng = np.random.default_rng(0)
    d = np.concatenate([rng.lognormal(7.0, 0.3, 120), rng.lognormal(9.5, 0.4, 80)])
    fit = fit_lognormal_mixture(d, random_state=0)
    assert fit.mixture.n_components == 2
    assert min(fit.aic_by_k, key=fit.aic_by_k.get) == 2
    assert fit.mixture.weights.sum() == pytest.approx(1.0)
    x = np.log(d)[:, None]
    gm = GaussianMixture(2, n_init=5, random_state=0, tol=1e-8).fit(x)
    ll_sk = gm.score(x) * x.shape[0]
    assert fit.log_likelihood == pytest.approx(ll_sk, abs=1e-3 * abs(ll_sk))
    order = np.argsort(fit.mixture.p1)
    np.testing.assert_allclose(fit.mixture.p1[order], np.sort(gm.means_.ravel()), atol=1e-3)


def test_em_single_cluster_and_determinism() -> None:
    rng = np.random.default_rng(1)
    d = rng.lognormal(8.0, 0.5, 300)
    a = fit_lognormal_mixture(d, random_state=3)
    b = fit_lognormal_mixture(d, random_state=3)
    assert a.mixture.n_components == 1
    assert a.mixture.p1[0] == pytest.approx(np.log(d).mean(), abs=1e-9)
    assert a.mixture.to_dict() == b.mixture.to_dict()
    with pytest.raises(EstimatorError, match="no positive durations"):
        fit_lognormal_mixture(np.array([0.0, -1.0]))


def test_pelt_finds_change_points() -> None:
    rng = np.random.default_rng(2)
    x = np.repeat([1, 0, 1, 0], [60, 40, 80, 50])
    y = np.where(rng.random(x.size) < 0.05, 1 - x, x)
    b = segment_stream(y)
    t = np.arange(x.size, dtype=float)
    p, a, lab = runs_from_segments(t, y, b)
    # merged runs: present 60 (censored first), absent 40, present 80, absent 50 (censored last)
    assert np.mean(lab == x) > 0.97
    assert a.size == 1 and abs(a[0] - 40) <= 3
    assert p.size == 1 and abs(p[0] - 80) <= 3


def test_runs_from_ground_truth() -> None:
    t = np.arange(0, 100, 1.0)
    x = (np.mod(t, 20) < 12).astype(np.int8)
    p, a = runs_from_ground_truth(t, x)
    assert np.all(p == 12) and np.all(a == 8)


def test_error_rates() -> None:
    rng = np.random.default_rng(3)
    lab = (rng.random(20000) < 0.5).astype(np.int8)
    flip = np.where(lab == 1, rng.random(lab.size) < 0.08, rng.random(lab.size) < 0.15)
    y = np.where(flip, 1 - lab, lab)
    pm, pf = estimate_error_rates(y, lab)
    assert pm == pytest.approx(0.08, abs=0.01) and pf == pytest.approx(0.15, abs=0.01)
