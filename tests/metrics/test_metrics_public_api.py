"""The public surface of psg_data.metrics: __all__ is complete and importable."""

from __future__ import annotations

import importlib
import subprocess
import sys

import psg_data.metrics as metrics

SUBMODULES = ["_classification", "_navigation", "_time_weights"]


def test_all_is_complete_and_resolvable():
    exported = set(metrics.__all__)
    assert len(exported) == len(metrics.__all__)
    for name in metrics.__all__:
        assert hasattr(metrics, name), name
    for mod in SUBMODULES:
        sub = importlib.import_module(f"psg_data.metrics.{mod}")
        missing = set(sub.__all__) - exported
        assert not missing, f"{mod}: {sorted(missing)} not re-exported"


def test_import_stays_light():
    code = (
        "import sys, psg_data.metrics; "
        "heavy = [m for m in ('sklearn', 'scipy', 'pandas', 'matplotlib', 'cv2', 'open3d') if m in sys.modules]; "
        "print(','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_docstring_examples():
    import doctest

    for mod in SUBMODULES:
        sub = importlib.import_module(f"psg_data.metrics.{mod}")
        res = doctest.testmod(sub)
        assert res.failed == 0, mod
