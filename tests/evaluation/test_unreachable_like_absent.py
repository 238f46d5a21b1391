"""Object navigation scored with reachability both ways: unreachable targets count like absent ones."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from psg_data.errors import EvaluationError
from psg_data.evaluation._navigation_scores import score_records
from psg_data.navigation import NavigationOptions


def _df(unreachable_aborted: bool) -> pd.DataFrame:
    return pd.DataFrame({
        "category": ["static", "static", "dynamic", "dynamic", "absent", "absent", "dynamic"],
        "reachable": [True, True, True, True, False, False, False],
        "success": [True, False, True, False, False, False, False],
        "aborted": [False, True, False, False, True, False, unreachable_aborted],
        "path_m": [4.0, 0.0, 10.0, 6.0, 3.0, 8.0, 0.0 if unreachable_aborted else 2.0],
        "shortest_path_m": [4.0, 5.0, 5.0, 2.0, np.nan, np.nan, np.nan],
    })


@pytest.mark.parametrize("aborted", [False, True])
def test_unreachable_target_scored_like_an_absent_one(aborted: bool) -> None:
    df = _df(aborted)
    base = score_records(df)
    s = score_records(df, unreachable="like_absent")
    # the per-category columns keep the reachable view, the absent column the absent targets
    for k in ("static_sr", "dynamic_sr", "dynamic_spl", "absent_ar", "absent_dist_m"):
        assert s[k] == base[k]
    # overall: 4 reachable present + 2 absent + 1 unreachable; a correct decline is a success
    assert base["overall_sr"] == pytest.approx(3 / 6)
    assert s["overall_sr"] == pytest.approx((3 + aborted) / 7)
    assert s["overall_spl"] == pytest.approx((1 + 0 + 0.5 + 0 + 1 + 0 + aborted) / 7)


def test_unknown_rule_rejected() -> None:
    with pytest.raises(EvaluationError, match="unreachable"):
        score_records(_df(False), unreachable="ignore")
    assert NavigationOptions(unreachable="like_absent").unreachable == "like_absent"
