"""The per-edge scores with shared confusion masks and counts equal main's (kept in
_edge_score_reference.py) bit for bit, for every convention, threshold ties, zero weights and empty input."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.evaluation._edge_run import ScoreConfig, _score
from tests.evaluation._edge_score_reference import reference_score

_CONV = st.sampled_from(["reference", "sklearn"])


@settings(max_examples=400, deadline=None, derandomize=True)
@given(st.integers(0, 10_000), st.integers(0, 300), _CONV, _CONV, st.sampled_from([0.5, 0.3, 0.0, 1.0]),
       st.floats(0.0, 1.0))
def test_score_equals_main_bit_for_bit(seed: int, n: int, conv: str, sample_conv: str, threshold: float,
                                       zero_share: float) -> None:
    r = np.random.default_rng(seed)
    y = r.integers(0, 2, n).astype(np.int64)
    b = np.where(r.random(n) < 0.2, threshold, r.random(n))  # ties with the threshold included
    b = np.where(r.random(n) < 0.1, r.integers(0, 2, n).astype(np.float64), b)
    w = np.where(r.random(n) < zero_share, 0.0, r.exponential(900.0, n))
    cfg = ScoreConfig("adaptive", 7200.0, threshold, conv, sample_conv, (-1, -2))
    got, want = _score(y, b, w, cfg), reference_score(y, b, w, cfg)
    assert got.keys() >= want.keys()
    assert repr({k: got[k] for k in want}) == repr(want)  # repr: every float exactly, NaN equal to NaN


def test_one_class_and_no_weight_edges() -> None:
    cfg = ScoreConfig("adaptive", 0.0, 0.5, "reference", "sklearn", ())
    for y, b, w in [(np.ones(5, np.int64), np.full(5, 0.7), np.zeros(5)),
                    (np.zeros(4, np.int64), np.array([0.1, 0.5, 0.9, 0.5]), np.array([1.0, 0.0, 2.5, 3.0])),
                    (np.zeros(0, np.int64), np.zeros(0), np.zeros(0))]:
        assert repr(_score(y, b, w, cfg)) == repr(reference_score(y, b, w, cfg))
