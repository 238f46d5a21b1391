"""segment_stream gives the boundaries of its reference (main aaa7199's PELT, kept in
_segmentation_reference.py) on random, blocky and noisy 0/1 streams of every size, with every
minimum segment and penalty, and on long minute-like streams."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators._segmentation import segment_stream
from tests.estimators._segmentation_reference import segment_stream as reference


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(0, 1), max_size=160), st.integers(1, 9), st.sampled_from([0.0, 0.5, 1.0, 3.0, 7.5]))
def test_random_streams(y: list[int], min_size: int, penalty: float) -> None:
    np.testing.assert_array_equal(segment_stream(y, min_size=min_size, penalty=penalty),
                                  reference(y, min_size=min_size, penalty=penalty))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1), st.integers(1, 40)), min_size=1, max_size=30), st.integers(0, 2**31),
       st.sampled_from([0.0, 0.03, 0.2]), st.integers(1, 8))
def test_blocky_noisy_streams(runs: list[tuple[int, int]], seed: int, flip: float, min_size: int) -> None:
    y = np.repeat([v for v, _ in runs], [n for _, n in runs])
    rng = np.random.default_rng(seed)
    y = np.where(rng.random(y.size) < flip, 1 - y, y)
    np.testing.assert_array_equal(segment_stream(y, min_size=min_size), reference(y, min_size=min_size))


def test_long_minute_like_stream() -> None:
    rng = np.random.default_rng(5)
    y = np.repeat(rng.integers(0, 2, size=60), rng.integers(20, 300, size=60))
    y = np.where(rng.random(y.size) < 0.02, 1 - y, y)
    got = segment_stream(y)
    np.testing.assert_array_equal(got, reference(y))
    assert got[0] == 0 and got[-1] == y.size and got.size > 10  # a real segmentation, not the trivial one
