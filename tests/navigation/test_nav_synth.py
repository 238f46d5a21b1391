"""The oracle and the last-seen map on the synthetic three-room lab."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.navigation import NavigationEnv, run_navigation


@pytest.mark.slow
def test_oracle_and_last_seen_on_synthetic_lab(tmp_path):
    from psg_data.synth._model import LabModel

    lab = LabModel(seed=0)
    env = NavigationEnv.from_lab(lab)
    assert len(env.receptacles) == 28 and len(env.doors) == 2 and len(env.object_ids) == 21
    # the map observations agree with the dense ground truth at the scan times
    for s in env.map_streams[:10]:
        o, r = s.edge
        assert [int(env.gt_at(o, t) == r) for t in s.t_s] == s.y.tolist()
    res = run_navigation(env, ["oracle", "last_seen_map"], seed=0, n_queries=80, out_dir=tmp_path)
    rec = res.records
    orc = rec[rec["method"] == "oracle"]
    present = orc[(orc["category"] != "absent") & orc["reachable"]]
    assert len(present) > 10 and present["success"].all()
    assert np.allclose(present["path_m"], present["shortest_path_m"])
    assert orc.loc[orc["category"] == "absent", "aborted"].all()
    ls = rec[rec["method"] == "last_seen_map"]
    st = ls[(ls["category"] == "static") & ls["reachable"]]
    assert st["success"].all()  # static objects are where they were last seen
    dyn = ls[(ls["category"] == "dynamic") & ls["reachable"]]
    assert not dyn["success"].all()  # moved objects are not where they were last seen
    summ = res.summary.set_index("method")
    assert summ.loc["oracle", "overall_sr_mean"] == 1.0
    assert summ.loc["oracle", "overall_spl_mean"] == pytest.approx(1.0, abs=1e-12)
    assert summ.loc["last_seen_map", "overall_sr_mean"] < 1.0
    # the static objects of the lab never move: their queries are 'static' or 'absent', never 'dynamic'
    roles = env.extra["roles"]
    assert not any(roles[o] == "static" for o in orc.loc[orc["category"] == "dynamic", "object_id"])
