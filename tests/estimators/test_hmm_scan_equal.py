"""The HMM's prefix products (recursive doubling, scaled) equal main aaa7199's to the bit for every
number of states (the elementwise and the reduction branch of the scaling), objects and lengths,
including lengths that are not powers of two and a single step."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.estimators._hmm import _prefix_products, _transitions
from tests.estimators._hmm_scan_reference import _prefix_products as reference


@pytest.mark.parametrize("n_s", [1, 2, 3, 4, 5, 11])
@pytest.mark.parametrize("n_obj,n_t", [(1, 1), (1, 2), (3, 7), (2, 513), (1, 4096)])
def test_prefix_products_equal_the_reference(n_s: int, n_obj: int, n_t: int) -> None:
    rng = np.random.default_rng(n_s * 1000 + n_t)
    d = rng.dirichlet(np.ones(n_s), size=n_obj)
    a = np.where(rng.random((n_obj, n_t))[:, :, None, None] < 0.1, _transitions(0.4, d)[:, None],
                 _transitions(0.8, d)[:, None])
    m = a * np.exp(np.log(rng.random((n_obj, n_t, n_s))) * 30.0)[:, :, None, :]  # tiny emissions: scaling matters
    got_p, got_c = _prefix_products(m)
    ref_p, ref_c = reference(m.copy())
    np.testing.assert_array_equal(got_p, ref_p)
    np.testing.assert_array_equal(got_c, ref_c)
    assert np.isfinite(got_c).all() and (got_c < 0).any()  # the scales were used
