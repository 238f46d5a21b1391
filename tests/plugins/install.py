"""Install ``psg_hostile_plugin`` into a folder as pip would: the module and a dist-info with its entry points."""

from __future__ import annotations

import shutil
from pathlib import Path

from tests.plugins.psg_hostile_plugin import MODES

HERE = Path(__file__).resolve().parent


def install_hostile_plugin(site: Path) -> Path:
    """``site`` holding the plugin module and ``psg_hostile_plugin-0.1.dist-info`` (group ``psg_data.estimators``)."""
    site.mkdir(parents=True, exist_ok=True)
    shutil.copy(HERE / "psg_hostile_plugin.py", site / "psg_hostile_plugin.py")
    info = site / "psg_hostile_plugin-0.1.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: psg-hostile-plugin\nVersion: 0.1\n")
    lines = [f"hostile_{m} = psg_hostile_plugin:Hostile_{m}" for m in MODES]
    (info / "entry_points.txt").write_text("[psg_data.estimators]\n" + "\n".join(lines) + "\n")
    return site
