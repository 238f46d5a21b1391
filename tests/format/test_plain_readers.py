"""The format is readable without psg-data: plain pandas / pyarrow in a fresh process."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def test_tables_open_without_psg_data(make_dataset) -> None:
    root = make_dataset()
    code = textwrap.dedent(f"""
        import json, sys, pathlib
        import pandas as pd, pyarrow.parquet as pq
        root = pathlib.Path({str(root)!r})
        manifest = json.loads((root / "dataset.json").read_text())
        assert manifest["format"] == "psg-dataset"
        for name in ["cameras", "scans", "frames", "rooms", "receptacles", "doors", "door_states",
                     "objects", "schedule", "files"]:
            df = pd.read_parquet(root / "tables" / f"{{name}}.parquet")
            t = pq.read_table(root / "tables" / f"{{name}}.parquet")
            assert len(df) == t.num_rows
        frames = pd.read_parquet(root / "tables/frames.parquet")
        import numpy as np
        T = np.stack(frames["T_world_camera"].to_numpy()).reshape(-1, 4, 4)
        assert np.allclose(T[:, 3], [0, 0, 0, 1])
        assert (root / frames["depth_path"][0]).is_file()
        assert "psg_data" not in sys.modules
        print("plain-ok", len(frames))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "plain-ok 12"


def test_import_is_light() -> None:
    code = ("import sys, psg_data; heavy = [m for m in ('cv2', 'open3d', 'pyarrow', 'pandas', 'matplotlib', "
            "'sklearn', 'scipy') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
