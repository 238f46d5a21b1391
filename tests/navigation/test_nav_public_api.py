"""The public surface of psg_data.navigation: __all__ is complete and the import stays light."""

from __future__ import annotations

import importlib
import subprocess
import sys

import psg_data.navigation as nav

SUBMODULES = ["psg_data.navigation." + m for m in ("_env", "_queries", "_baselines", "_agent", "_runner", "_plots",
                                                     "_options", "_doors", "_door_dataset",
                                                     "_sim_agent", "_sim_benchmark")]
SUBMODULES += ["psg_data.maps._grid", "psg_data.maps._planner", "psg_data.graph._sources"]
"""Modules whose public names psg_data.navigation exports (the maps and label sources moved below it, issue 26)."""


def test_all_is_complete_and_resolvable():
    assert len(set(nav.__all__)) == len(nav.__all__)
    for name in nav.__all__:
        assert hasattr(nav, name), name
    for mod in SUBMODULES:
        sub = importlib.import_module(mod)
        missing = set(sub.__all__) - set(nav.__all__)
        assert not missing, f"{mod}: {sorted(missing)} not re-exported"


def test_import_stays_light():
    code = ("import sys, psg_data.navigation; "
            "print(','.join(m for m in ('scipy', 'pandas', 'matplotlib', 'cv2', 'open3d', 'networkx') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""
