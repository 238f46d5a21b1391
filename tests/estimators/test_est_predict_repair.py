"""``BaseFilter.predict``'s repair of a built-in filter's values (NaN -> 0.5, then [0, 1]) with two ufuncs
equals main's ``np.clip(np.nan_to_num(out, nan=0.5), 0, 1)`` byte for byte: NaN, +-inf, -0.0, values
outside [0, 1], any shape (0-d included)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from psg_data.estimators._common import BaseFilter


class _Fixed(BaseFilter):
    """A built-in-module filter (its predictions are repaired) that returns given values."""

    values: np.ndarray = np.zeros(0)

    def _predict(self, t: np.ndarray) -> np.ndarray:
        return self.values.reshape(-1)[: t.size]

    def _update_many(self, t: np.ndarray, y: np.ndarray) -> None:
        return None


_Fixed.__module__ = "psg_data.estimators._test_fixed"
_Fixed._repairs_predictions = True

_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0.0, -0.0, 1.0, 0.5, -1e-300, 1.0000000000000002, np.nan, np.inf, -np.inf]))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=2, max_side=6), elements=_VALUES))
def test_repair_equals_nan_to_num_then_clip(values: np.ndarray) -> None:
    f = _Fixed(("o", "r"))
    f.values = values
    got = f.predict(np.zeros(values.shape))
    want = np.clip(np.nan_to_num(values.astype(np.float64), nan=0.5), 0.0, 1.0)
    assert np.shape(got) == np.shape(want)
    assert np.asarray(got).tobytes() == np.asarray(want).tobytes()
    assert type(got) is type(want)
