"""ForwardBelief's kernel, the weekday pattern marginals and Perpetua's dominant terms (issue 45, point 2: made
cheap, results unchanged): bit-equal to the references kept in tests/estimators (_forward_kernel_reference.py:
main df3898b's kernel and marginals; MixtureFilter.dominant / component_log_evidence: what Perpetua's terms
computed before).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators._mixture import MixtureFilter
from psg_data.synth._process import ForwardBelief, weekday_pattern_marginals
from tests.estimators import _forward_kernel_reference as ref_kernel
from tests.estimators.test_est_filters_reference import H, _mixture
from tests.synth.test_process_exact import tiny_process
from tests.synth.test_process_mutants import _regime_process


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 50), k=st.integers(0, 3), zeros=st.floats(0.0, 0.9), regime=st.booleans())
def test_the_hour_kernel_is_bit_equal_to_main(seed: int, k: int, zeros: float, regime: bool) -> None:
    """The kernel on random beliefs (with zeros) equals main df3898b's bit for bit."""
    proc = _regime_process(seed, start_day=1, K=4) if regime else tiny_process(seed, K=4, S=4, max_hi=3)
    b = ForwardBelief(proc, proc.entities["obj"]).start()
    rng = np.random.default_rng(seed)
    beta = rng.random(b.alpha.shape) * (rng.random(b.alpha.shape) >= zeros)
    np.testing.assert_array_equal(b._hour_kernel(beta, k), ref_kernel.hour_kernel(b, beta, k))


@settings(max_examples=80, deadline=None)
@given(data=st.data(), family=st.sampled_from(["lognormal", "exponential"]), emergence=st.booleans(),
       noise=st.sampled_from([0.0, 0.05, 0.3]))
def test_dominant_evidence_is_what_dominant_and_the_evidence_give(data: st.DataObject, family: str,
                                                                   emergence: bool, noise: float) -> None:
    """After every step (and after a new prior) the step's dominant component and evidence are the arrays'."""
    m = MixtureFilter(_mixture(data.draw, family), noise, noise, emergence=emergence)
    n = data.draw(st.integers(1, 25))
    gaps = data.draw(st.lists(st.sampled_from([0.0, 0.01, 0.5, 2.0, 30.0, 400.0]), min_size=n, max_size=n))
    ys = data.draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))
    t = 1.7e9
    for i, (gap, y) in enumerate(zip(gaps, ys)):
        t += gap * H
        m.update(t, y)
        if i % 7 == 3:  # a new prior (as a restart sets): the step's values no longer hold
            m.log_prior = m.log_prior[::-1].copy()
        k = m.dominant()
        assert m.dominant_evidence() == (k, float(m.component_log_evidence()[k]))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 50), shifted=st.sampled_from([(), (1, 3)]), weeks=st.integers(1, 30))
def test_weekday_pattern_marginals_are_bit_equal_to_main(seed: int, shifted: tuple[int, ...], weeks: int) -> None:
    """The long-run weekday marginals (the LLM schedules' modal patterns) equal main df3898b's bit for bit."""
    proc = _regime_process(seed, start_day=1, shifted=shifted)
    allowed = np.random.default_rng(seed).random((7, 2)) < 0.7
    allowed[~allowed.any(axis=1), seed % 2] = True  # every weekday its own mask, none empty
    ent = dataclasses.replace(proc.entities["obj"], pattern_allowed=allowed)
    np.testing.assert_array_equal(weekday_pattern_marginals(proc, ent, weeks),
                                  ref_kernel.weekday_pattern_marginals(proc, ent, weeks))
