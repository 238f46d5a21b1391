"""The number of CPUs this process may run on (what ``--jobs -1`` and thread budgets use)."""

from __future__ import annotations

import os

__all__ = ["available_cpus"]


def available_cpus() -> int:
    """CPUs this process may use: its affinity mask where the OS reports one (taskset, cgroup
    cpusets), else the machine's CPU count; at least 1.
    """
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1
