"""Rigid transforms for raw recordings: quaternions, time series of poses and a TF tree.

Conventions: quaternions are ``(x, y, z, w)`` (ROS order), transforms are 4x4 ``T_parent_child``
(maps points from ``child`` to ``parent``), stamps are int64 nanoseconds.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import ConversionError

__all__ = [
    "quat_xyzw_to_matrix",
    "matrix_to_quat_xyzw",
    "make_transform",
    "slerp",
    "PoseSeries",
    "TfBuffer",
]


def quat_xyzw_to_matrix(q: Iterable[float]) -> NDArray[np.float64]:
    """3x3 rotation of a (not necessarily unit) quaternion ``(x, y, z, w)``."""
    x, y, z, w = np.asarray(list(q), dtype=np.float64)
    n = x * x + y * y + z * z + w * w
    if not np.isfinite(n) or n < 1e-12:
        return np.full((3, 3), np.nan)
    s = 2.0 / n
    return np.array([
        [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
        [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
        [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
    ])


def matrix_to_quat_xyzw(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of a 3x3 rotation (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s])
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def make_transform(translation: Iterable[float], quat_xyzw: Iterable[float]) -> NDArray[np.float64]:
    """4x4 transform from a translation (metres) and a quaternion ``(x, y, z, w)``."""
    T = np.eye(4)
    T[:3, :3] = quat_xyzw_to_matrix(quat_xyzw)
    T[:3, 3] = np.asarray(list(translation), dtype=np.float64)
    return T


def slerp(q0: NDArray[np.float64], q1: NDArray[np.float64], a: float) -> NDArray[np.float64]:
    """Spherical linear interpolation between unit quaternions (shortest arc), ``a`` in [0, 1]."""
    q0 = np.asarray(q0, float) / np.linalg.norm(q0)
    q1 = np.asarray(q1, float) / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
        return q / np.linalg.norm(q)
    th = np.arccos(min(d, 1.0))
    return (np.sin((1 - a) * th) * q0 + np.sin(a * th) * q1) / np.sin(th)


@dataclass
class PoseSeries:
    """Time series of one transform, looked up with interpolation.

    Samples may arrive slightly out of order; they are kept sorted by stamp.
    """

    stamps: list[int] = field(default_factory=list)
    translations: list[NDArray[np.float64]] = field(default_factory=list)
    quats: list[NDArray[np.float64]] = field(default_factory=list)

    def add(self, stamp_ns: int, translation: Iterable[float], quat_xyzw: Iterable[float]) -> None:
        t = np.asarray(list(translation), dtype=np.float64)
        q = np.asarray(list(quat_xyzw), dtype=np.float64)
        i = bisect.bisect_right(self.stamps, stamp_ns)
        if i > 0 and self.stamps[i - 1] == stamp_ns:  # republished sample: last one wins
            self.translations[i - 1], self.quats[i - 1] = t, q
            return
        self.stamps.insert(i, int(stamp_ns))
        self.translations.insert(i, t)
        self.quats.insert(i, q)

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def last_stamp(self) -> int | None:
        return self.stamps[-1] if self.stamps else None

    def prune_before(self, stamp_ns: int) -> None:
        """Drop samples older than the last one at or before ``stamp_ns`` (bounded memory)."""
        i = bisect.bisect_right(self.stamps, stamp_ns) - 1
        if i > 0:
            del self.stamps[:i], self.translations[:i], self.quats[:i]

    def at(self, stamp_ns: int, max_gap_ns: int, tolerance_ns: int) -> NDArray[np.float64] | None:
        """4x4 transform at ``stamp_ns`` or None.

        Interpolates (lerp + slerp) between the two samples around ``stamp_ns`` if they are at
        most ``max_gap_ns`` apart; otherwise uses the nearest sample if it is within
        ``tolerance_ns``.
        """
        s = self.stamps
        if not s:
            return None
        i = bisect.bisect_left(s, stamp_ns)
        if i < len(s) and s[i] == stamp_ns:
            return make_transform(self.translations[i], self.quats[i])
        if 0 < i < len(s) and s[i] - s[i - 1] <= max_gap_ns:
            a = (stamp_ns - s[i - 1]) / (s[i] - s[i - 1])
            t = (1 - a) * self.translations[i - 1] + a * self.translations[i]
            return make_transform(t, slerp(self.quats[i - 1], self.quats[i], a))
        best = min((j for j in (i - 1, i) if 0 <= j < len(s)), key=lambda j: abs(s[j] - stamp_ns))
        if abs(s[best] - stamp_ns) <= tolerance_ns:
            return make_transform(self.translations[best], self.quats[best])
        return None


class TfBuffer:
    """The TF tree of a recording: static and dynamic edges, looked up at any time.

    Args:
        max_gap_ns: largest gap between two samples of a dynamic edge that is interpolated.
        tolerance_ns: largest distance to the nearest sample when not interpolating.
    """

    def __init__(self, max_gap_ns: int, tolerance_ns: int) -> None:
        self.max_gap_ns = int(max_gap_ns)
        self.tolerance_ns = int(tolerance_ns)
        self.static: dict[tuple[str, str], NDArray[np.float64]] = {}
        self.dynamic: dict[tuple[str, str], PoseSeries] = {}
        self._paths: dict[tuple[str, str], list[tuple[str, str, bool]] | None] = {}

    @staticmethod
    def _norm(frame: str) -> str:
        return frame.lstrip("/")

    def add(self, parent: str, child: str, stamp_ns: int, translation: Iterable[float],
            quat_xyzw: Iterable[float], *, static: bool) -> None:
        key = (self._norm(parent), self._norm(child))
        if key not in self.static and key not in self.dynamic:
            self._paths.clear()
        if static:
            self.static[key] = make_transform(translation, quat_xyzw)
        else:
            self.dynamic.setdefault(key, PoseSeries()).add(stamp_ns, translation, quat_xyzw)

    @property
    def frames(self) -> list[str]:
        return sorted({f for k in (*self.static, *self.dynamic) for f in k})

    def has_frame(self, frame: str) -> bool:
        return self._norm(frame) in self.frames

    def path(self, source: str, target: str) -> list[tuple[str, str, bool]] | None:
        """Edges ``(parent, child, forward)`` from ``source`` to ``target`` or None if disconnected."""
        source, target = self._norm(source), self._norm(target)
        key = (source, target)
        if key in self._paths:
            return self._paths[key]
        adj: dict[str, list[tuple[str, tuple[str, str, bool]]]] = {}
        for p, c in (*self.static, *self.dynamic):
            adj.setdefault(p, []).append((c, (p, c, True)))
            adj.setdefault(c, []).append((p, (p, c, False)))
        prev: dict[str, tuple[str, tuple[str, str, bool]] | None] = {source: None}
        queue = deque([source])
        while queue:
            f = queue.popleft()
            if f == target:
                break
            for g, edge in adj.get(f, []):
                if g not in prev:
                    prev[g] = (f, edge)
                    queue.append(g)
        if target not in prev:
            self._paths[key] = None
            return None
        edges: list[tuple[str, str, bool]] = []
        f = target
        while prev[f] is not None:
            g, edge = prev[f]  # type: ignore[misc]
            edges.append(edge)
            f = g
        edges.reverse()
        self._paths[key] = edges
        return edges

    def lookup(self, source: str, target: str, stamp_ns: int, where: str = "") -> NDArray[np.float64] | None:
        """``T_source_target`` at ``stamp_ns`` (None if a dynamic edge has no sample near it).

        Raises:
            ConversionError: the tree has no path between the two frames.
        """
        edges = self.path(source, target)
        if edges is None:
            raise ConversionError(
                f"{where}/tf: TF tree has no path from {source!r} to {target!r}; frames present: "
                f"{', '.join(self.frames) or 'none'} (ROS 2 bags often lack /tf_static: add it with "
                f"'static_transforms' in the config file)")
        T = np.eye(4)
        for p, c, forward in edges:
            if (p, c) in self.static:
                E = self.static[(p, c)]
            else:
                E = self.dynamic[(p, c)].at(stamp_ns, self.max_gap_ns, self.tolerance_ns)
                if E is None:
                    return None
            T = T @ (E if forward else invert(E))
        return T

    def last_dynamic_stamp(self) -> int | None:
        """Smallest over dynamic edges of their newest sample (None if no dynamic edge)."""
        last = [s.last_stamp for s in self.dynamic.values() if s.last_stamp is not None]
        return min(last) if last else None

    def prune_before(self, stamp_ns: int) -> None:
        for s in self.dynamic.values():
            s.prune_before(stamp_ns)


def invert(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of a rigid 4x4 transform."""
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out
