"""The analysis script of RESULTS.md 6.1 (docs/analysis/last_state_split.py): its last-observation lookup."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

_PATH = Path(__file__).resolve().parents[2] / "docs" / "analysis" / "last_state_split.py"
_spec = importlib.util.spec_from_file_location("last_state_split", _PATH)
assert _spec is not None and _spec.loader is not None
last_state_split = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(last_state_split)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 50), max_size=6), st.lists(st.integers(60, 200), max_size=8),
       st.lists(st.integers(0, 260), min_size=1, max_size=10), st.integers(0, 40), st.integers(0, 2**31 - 1))
def test_last_state_is_the_last_observation_a_horizon_before(hist_t: list[int], obs_t: list[int], t: list[int],
                                                             horizon: int, seed: int) -> None:
    """Against a brute-force scan of the observations, including edges with none."""
    rng = np.random.default_rng(seed)
    ht, ot = np.sort(np.asarray(hist_t, float)), np.sort(np.asarray(obs_t, float))
    hy, oy = rng.integers(0, 2, ht.size).astype(np.int8), rng.integers(0, 2, ot.size).astype(np.int8)
    got = last_state_split.last_state(np.asarray(t, float), (ht, hy), ot, oy, float(horizon))
    for ti, g in zip(t, got):
        # the filter has every training observation and the test ones at least a horizon old
        seen = [(x, int(y)) for x, y in zip(ht, hy)] + [(x, int(y)) for x, y in zip(ot, oy) if x <= ti - horizon]
        assert g == (seen[-1][1] if seen else -1)
