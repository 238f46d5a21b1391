"""Lazy, robust import of Open3D.

Open3D's Linux wheels link against ``libusb-1.0.so.0``, which minimal machines lack. When the
system library is missing, the copy shipped by the ``libusb-package`` wheel is preloaded so that the
dynamic linker resolves Open3D's dependency by soname. Import Open3D only through
:func:`import_open3d` so that ``import psg_data`` stays fast.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
from types import ModuleType

__all__ = ["import_open3d"]

_o3d: ModuleType | None = None


def _preload_libusb() -> None:
    if ctypes.util.find_library("usb-1.0"):
        return
    try:
        import libusb_package
    except ImportError:  # pragma: no cover - only on machines without the wheel
        return
    for path in sorted(glob.glob(os.path.join(os.path.dirname(libusb_package.__file__), "libusb*.so*"))):
        try:
            ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
            return
        except OSError:  # pragma: no cover
            continue


def import_open3d() -> ModuleType:
    """Return the ``open3d`` module, importing it on first use."""
    global _o3d
    if _o3d is None:
        _preload_libusb()
        import open3d  # noqa: PLC0415

        _o3d = open3d
    return _o3d
