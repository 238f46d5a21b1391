"""Door label rows, visibility rows and door streams through the labelling pipeline and the CLI."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.labeling import label_dataset, label_streams, load_label_streams, observe_doors
from psg_data.loaders import open_dataset
from psg_data.schemas.validate import validate_dataset


def test_label_sources_write_valid_door_rows(door_lab_copy) -> None:  # type: ignore[no-untyped-def]
    for src in ("privileged", "gt", "noisy:0.2", "observed"):
        label_dataset(door_lab_copy, src, seed=1)
    assert validate_dataset(door_lab_copy) == []
    ds = open_dataset(door_lab_copy)
    t = ds.table("labels").to_pandas()
    doors = t[t.object_id.isin(list(ds.doors))]
    assert set(doors.receptacle_id) == {"open", "closed"}
    assert set(doors.source) == {"privileged", "gt", "noisy:0.2,0.2", "observed"}
    vis = ds.table("visibility").to_pandas()
    dv = vis[vis.kind == "door"]
    assert len(dv) == len(ds.scan_ids) * len(ds.doors)
    obs = observe_doors(ds)
    for src in ("privileged", "observed"):
        d = doors[doors.source == src]
        opened = d[d.receptacle_id == "open"].set_index(["scan_id", "object_id"]).code
        for (sid, did), code in opened.items():
            s, k = obs.scan_ids.index(sid), obs.door_ids.index(did)
            seen = bool(dv[(dv.scan_id == sid) & (dv.id == did)].visible.iloc[0])
            assert seen == bool(obs.visible[s, k])
            assert (code >= 0) == seen  # -1 exactly when the door was not seen
    # privileged and observed agree wherever the door was seen (the state read from the images is right)
    p = doors[doors.source == "privileged"].set_index(["scan_id", "object_id", "receptacle_id"]).code
    o = doors[doors.source == "observed"].set_index(["scan_id", "object_id", "receptacle_id"]).code
    assert (p == o.reindex(p.index)).all()
    g = doors[doors.source == "gt"]
    assert (g.code >= 0).all()
    # the noisy door codes are consistent pairs (open edge = 1 - closed edge) and differ from privileged somewhere
    n = doors[doors.source == "noisy:0.2,0.2"].pivot_table(index=["scan_id", "object_id"], columns="receptacle_id",
                                                           values="code")
    seen_n = n["open"] >= 0
    assert np.all(n["open"][seen_n] + n["closed"][seen_n] == 1)


def test_streams_split_objects_and_doors(door_lab_copy) -> None:  # type: ignore[no-untyped-def]
    label_dataset(door_lab_copy, "privileged")
    ds = open_dataset(door_lab_copy)
    objs = load_label_streams(ds, "privileged")
    both = load_label_streams(ds, "privileged", doors=True)
    only = load_label_streams(ds, "privileged", doors="only")
    door_ids = set(ds.doors)
    assert all(s.edge[0] not in door_ids for s in objs)
    assert {s.edge for s in only} == {(d, st) for d in door_ids for st in ("open", "closed")}
    assert [s.edge for s in both] == [s.edge for s in objs] + [s.edge for s in only]
    # same streams on the fly
    fly = label_streams(ds, "privileged", doors="only")
    assert [(s.edge, s.t_s.tolist(), s.y.tolist()) for s in fly] == [(s.edge, s.t_s.tolist(), s.y.tolist()) for s in only]
    by = {s.edge: s for s in only}
    for d in door_ids:
        o, c = by[(d, "open")], by[(d, "closed")]
        assert np.array_equal(o.t_s, c.t_s) and np.all(o.y + c.y == 1)
    with pytest.raises(Exception, match="doors="):
        load_label_streams(ds, "privileged", doors="yes")


def test_an_estimator_fits_on_door_streams(door_lab_copy) -> None:  # type: ignore[no-untyped-def]
    from psg_data.estimators import get_estimator

    label_dataset(door_lab_copy, "observed")
    streams = load_label_streams(door_lab_copy, "observed", doors="only")
    open_streams = [s for s in streams if s.edge[1] == "open" and len(s)]
    assert open_streams
    est = get_estimator("time_of_week_frequency").fit(open_streams, timezone="America/Toronto")
    for s in open_streams:
        f = est.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        p = f.predict(np.array([s.t_s[-1] + 3600.0, s.t_s[-1] + 86400.0]))
        assert np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 1))


def test_cli_label_observed_then_validate(door_lab_copy) -> None:  # type: ignore[no-untyped-def]
    from psg_data.cli.psg_data_cmd import main

    r = CliRunner().invoke(main, ["label", str(door_lab_copy), "--source", "observed", "-q"])
    assert r.exit_code == 0, r.output
    assert "state agrees with door_states in" in r.output
    # the door-only source reports its door-state edges (2 doors x open/closed), not "0 edges"
    assert "source observed: 4 door-state edges" in r.output and " 0 edges" not in r.output
    r = CliRunner().invoke(main, ["validate", str(door_lab_copy)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["label", str(door_lab_copy), "--source", "gt", "--no-doors", "-q"])
    assert r.exit_code == 0, r.output
    t = open_dataset(door_lab_copy).table("labels").to_pandas()
    assert not t[(t.source == "gt") & t.object_id.str.startswith("door_")].shape[0]


def test_observed_needs_doors(make_dataset, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from psg_data.errors import LabelingError
    from psg_data.labeling import parse_source

    assert parse_source("observed").kind == "observed"
    with pytest.raises(LabelingError):
        parse_source("observd")
