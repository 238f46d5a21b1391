"""psg-eval --task navigation with label sources and protocols (small generated dataset)."""

from __future__ import annotations

from click.testing import CliRunner


def test_cli_navigation_with_labels_and_protocols(nav_dataset, tmp_path) -> None:  # type: ignore[no-untyped-def]
    import json

    from psg_data.cli.psg_eval_cmd import main

    out = tmp_path / "real"
    r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", str(nav_dataset), "--labels", "noisy:0.1",
                                  "--protocol", "paper-real", "-e", "time_of_week_frequency", "--no-references",
                                  "--seeds", "1", "--out", str(out), "-q", "--no-plots"])
    assert r.exit_code == 0, r.output
    assert "Static (10)" in r.output and "Dynamic (10)" in r.output and "Absent (5)" in r.output
    assert "Overall (25)" in r.output and "protocol paper-real" in r.output
    info = json.loads((out / "results.json").read_text())["info"]
    assert info["protocol"] == "paper-real" and info["labels"] == "noisy:0.1" and info["door_belief"] == "predicted"
    assert info["quotas"] == {"static": 10, "dynamic": 10, "absent": 5} and info["start"] == "fixed"
    assert len(list((out / "queries").glob("*.parquet"))) == 1
    for args, msg in ((["--protocol", "paper-real", "--queries", "30"], "has 25 queries"),
                      (["--labels", "observed"], "door-only"),
                      (["--labels", "privileged"], "psg-data label")):
        r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", str(nav_dataset), "-e", "last_seen",
                                      "--no-references", "--out", str(tmp_path / "bad"), "-q", *args])
        assert r.exit_code == 1 and msg in r.output and "Traceback" not in r.output, r.output
        assert not (tmp_path / "bad").exists()
