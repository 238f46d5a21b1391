"""Rigid transforms for raw recordings: quaternions, time series of poses and a TF tree.

Conventions: quaternions are ``(x, y, z, w)`` (ROS order), transforms are 4x4 ``T_parent_child``
(maps points from ``child`` to ``parent``), stamps are int64 nanoseconds.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import ConversionError

__all__ = [
    "matrix_to_quat_xyzw",
    "make_transform",
    "PoseSeries",
    "TfBuffer",
]


Pose7 = tuple[float, float, float, float, float, float, float]
"""A rigid transform as plain floats ``(tx, ty, tz, qx, qy, qz, qw)`` with a unit quaternion."""

_NAN7: Pose7 = (math.nan,) * 7


def _pose7(t: Iterable[float], q: Iterable[float]) -> Pose7:
    """Translation and (normalised) quaternion as a Pose7; all NaN if the quaternion is degenerate."""
    tx, ty, tz = t
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or n < 1e-6:
        return _NAN7
    return (float(tx), float(ty), float(tz), x / n, y / n, z / n, w / n)


def _compose(a: Pose7, b: Pose7) -> Pose7:
    """``a @ b`` for Pose7 transforms (translation a.t + R_a b.t, quaternion product a.q b.q)."""
    ax, ay, az, aw = a[3], a[4], a[5], a[6]
    bx, by, bz = b[0], b[1], b[2]
    # R_a b.t = b.t + 2 w (u x b.t) + 2 u x (u x b.t), u = a's vector part
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    dx, dy, dz = ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx
    qx, qy, qz, qw = b[3], b[4], b[5], b[6]
    return (a[0] + bx + 2.0 * (aw * cx + dx), a[1] + by + 2.0 * (aw * cy + dy), a[2] + bz + 2.0 * (aw * cz + dz),
            aw * qx + ax * qw + ay * qz - az * qy,
            aw * qy - ax * qz + ay * qw + az * qx,
            aw * qz + ax * qy - ay * qx + az * qw,
            aw * qw - ax * qx - ay * qy - az * qz)


def _inverse(a: Pose7) -> Pose7:
    conj: Pose7 = (0.0, 0.0, 0.0, -a[3], -a[4], -a[5], a[6])
    t = _compose(conj, (a[0], a[1], a[2], 0.0, 0.0, 0.0, 1.0))
    return (-t[0], -t[1], -t[2], -a[3], -a[4], -a[5], a[6])


def _matrix(a: Pose7) -> NDArray[np.float64]:
    x, y, z, w = a[3], a[4], a[5], a[6]
    return np.array((1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), a[0],
                     2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), a[1],
                     2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), a[2],
                     0.0, 0.0, 0.0, 1.0)).reshape(4, 4)


def _interpolate(p: Pose7, r: Pose7, a: float) -> Pose7:
    """Lerp of the translations and slerp (shortest arc) of the unit quaternions, ``a`` in [0, 1]."""
    px, py, pz, pw = p[3], p[4], p[5], p[6]
    rx, ry, rz, rw = r[3], r[4], r[5], r[6]
    d = px * rx + py * ry + pz * rz + pw * rw
    if d < 0:
        rx, ry, rz, rw, d = -rx, -ry, -rz, -rw, -d
    if d > 1.0 - 1e-10:  # parallel to within ~1e-5 rad: normalised lerp (error ~ angle^3, below 1e-15)
        qx, qy, qz, qw = px + a * (rx - px), py + a * (ry - py), pz + a * (rz - pz), pw + a * (rw - pw)
        n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    else:
        th = math.acos(min(d, 1.0))
        st = math.sin(th)
        s0, s1 = math.sin((1 - a) * th) / st, math.sin(a * th) / st
        qx, qy, qz, qw = s0 * px + s1 * rx, s0 * py + s1 * ry, s0 * pz + s1 * rz, s0 * pw + s1 * rw
    return (p[0] + a * (r[0] - p[0]), p[1] + a * (r[1] - p[1]), p[2] + a * (r[2] - p[2]), qx, qy, qz, qw)


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
    return _matrix(_pose7(tuple(translation), tuple(quat_xyzw)))


@dataclass
class PoseSeries:
    """Time series of one transform, looked up with interpolation.

    Samples may arrive slightly out of order; they are kept sorted by stamp. Each sample is kept
    as a :data:`Pose7` of plain floats: a lookup interpolates in Python floats, which for one pose
    costs less than the small numpy operations it replaces.
    """

    stamps: list[int] = field(default_factory=list)
    samples: list[Pose7] = field(default_factory=list)

    def add(self, stamp_ns: int, translation: Iterable[float], quat_xyzw: Iterable[float]) -> None:
        """Add a sample: translation (metres) and quaternion ``(x, y, z, w)`` at ``stamp_ns``."""
        self.add7(int(stamp_ns), _pose7(translation, quat_xyzw))

    def add7(self, stamp_ns: int, sample: Pose7) -> None:
        """Add a sample given as a :data:`Pose7` (kept in stamp order; a repeated stamp replaces the sample)."""
        s = self.stamps
        if not s or stamp_ns > s[-1]:  # the usual case: in order
            s.append(stamp_ns)
            self.samples.append(sample)
            return
        i = bisect.bisect_right(s, stamp_ns)
        if i > 0 and s[i - 1] == stamp_ns:  # republished sample: last one wins
            self.samples[i - 1] = sample
            return
        s.insert(i, stamp_ns)
        self.samples.insert(i, sample)

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def last_stamp(self) -> int | None:
        """Stamp of the newest sample, or None."""
        return self.stamps[-1] if self.stamps else None

    def prune_before(self, stamp_ns: int) -> None:
        """Drop samples older than the last one at or before ``stamp_ns`` (bounded memory)."""
        i = bisect.bisect_right(self.stamps, stamp_ns) - 1
        if i > 0:
            del self.stamps[:i], self.samples[:i]

    def at7(self, stamp_ns: int, max_gap_ns: int, tolerance_ns: int) -> Pose7 | None:
        """The transform at ``stamp_ns`` as a :data:`Pose7`, or None (see :meth:`at`)."""
        s = self.stamps
        if not s:
            return None
        i = bisect.bisect_left(s, stamp_ns)
        n = len(s)
        if i < n and s[i] == stamp_ns:
            return self.samples[i]
        if 0 < i < n and s[i] - s[i - 1] <= max_gap_ns:
            return _interpolate(self.samples[i - 1], self.samples[i], (stamp_ns - s[i - 1]) / (s[i] - s[i - 1]))
        best = i - 1 if i == n or (i > 0 and stamp_ns - s[i - 1] <= s[i] - stamp_ns) else i
        if abs(s[best] - stamp_ns) <= tolerance_ns:
            return self.samples[best]
        return None

    def at(self, stamp_ns: int, max_gap_ns: int, tolerance_ns: int) -> NDArray[np.float64] | None:
        """4x4 transform at ``stamp_ns`` or None.

        Interpolates (lerp + slerp) between the two samples around ``stamp_ns`` if they are at
        most ``max_gap_ns`` apart; otherwise uses the nearest sample if it is within
        ``tolerance_ns``.
        """
        p = self.at7(stamp_ns, max_gap_ns, tolerance_ns)
        return None if p is None else _matrix(p)


class TfBuffer:
    """The TF tree of a recording: static and dynamic edges, looked up at any time.

    Args:
        max_gap_ns: largest gap between two samples of a dynamic edge that is interpolated.
        tolerance_ns: largest distance to the nearest sample when not interpolating.
    """

    def __init__(self, max_gap_ns: int, tolerance_ns: int) -> None:
        self.max_gap_ns = int(max_gap_ns)
        self.tolerance_ns = int(tolerance_ns)
        self.static: dict[tuple[str, str], Pose7] = {}
        self.dynamic: dict[tuple[str, str], PoseSeries] = {}
        self._paths: dict[tuple[str, str], list[tuple[str, str, bool]] | None] = {}
        self._plans: dict[tuple[str, str], list[Any]] = {}
        """(source, target) -> the path with runs of static edges multiplied out (see lookup)."""

    @staticmethod
    def _norm(frame: str) -> str:
        return frame.lstrip("/")

    def add(self, parent: str, child: str, stamp_ns: int, translation: Iterable[float],
            quat_xyzw: Iterable[float], *, static: bool) -> None:
        """Add transform ``T_parent_child`` at ``stamp_ns`` (static: valid at every time)."""
        if not static:
            series = self.dynamic.get((parent, child))
            if series is not None:  # the usual case: a known dynamic edge with normalised names
                series.add7(int(stamp_ns), _pose7(translation, quat_xyzw))
                return
        key = (self._norm(parent), self._norm(child))
        if key not in self.static and key not in self.dynamic:
            self._paths.clear()
            self._plans.clear()
        pose = _pose7(translation, quat_xyzw)
        if static:
            if self.static.get(key) != pose:
                self._plans.clear()
            self.static[key] = pose
        else:
            series = self.dynamic.get(key)
            if series is None:
                series = self.dynamic[key] = PoseSeries()
            series.add7(int(stamp_ns), pose)

    @property
    def frames(self) -> list[str]:
        """Every frame of the tree, sorted."""
        return sorted({f for k in (*self.static, *self.dynamic) for f in k})

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
        key = (source, target)
        plan = self._plans.get(key)
        if plan is None:
            edges = self.path(source, target)
            if edges is None:
                raise ConversionError(
                    f"{where}/tf: TF tree has no path from {source!r} to {target!r}; frames present: "
                    f"{', '.join(self.frames) or 'none'} (ROS 2 bags often lack /tf_static: add it with "
                    f"'static_transforms' in the config file)")
            plan = self._plans[key] = self._plan(edges)
        T: Pose7 | None = None
        for step in plan:
            if len(step) == 7:
                E = step
            else:
                p, c, forward = step
                E = self.dynamic[(p, c)].at7(stamp_ns, self.max_gap_ns, self.tolerance_ns)
                if E is None:
                    return None
                if not forward:
                    E = _inverse(E)
            T = E if T is None else _compose(T, E)
        return np.eye(4) if T is None else _matrix(T)

    def _plan(self, edges: list[tuple[str, str, bool]]) -> list[Any]:
        """The path as steps: products of consecutive static edges (Pose7) and dynamic edges."""
        plan: list[Any] = []
        for p, c, forward in edges:
            if (p, c) in self.static:
                E = self.static[(p, c)] if forward else _inverse(self.static[(p, c)])
                if plan and len(plan[-1]) == 7:
                    plan[-1] = _compose(plan[-1], E)
                else:
                    plan.append(E)
            else:
                plan.append((p, c, forward))
        return plan

    def horizon(self, source: str, target: str) -> int | None:
        """Newest stamp up to which every dynamic edge on the path ``source`` -> ``target`` has samples
        (the smallest of their newest stamps; a static path has no limit), or None without a path.
        """
        key = (source, target)
        plan = self._plans.get(key)
        if plan is None:
            edges = self.path(source, target)
            if edges is None:
                return None
            plan = self._plans[key] = self._plan(edges)
        h = 1 << 62
        for step in plan:
            if len(step) == 3:
                last = self.dynamic[(step[0], step[1])].last_stamp
                if last is None:
                    return None
                if last < h:
                    h = last
        return h

    def prune_before(self, stamp_ns: int) -> None:
        """Drop, on every dynamic edge, the samples older than its last one at or before ``stamp_ns``."""
        for s in self.dynamic.values():
            s.prune_before(stamp_ns)


def invert(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of a rigid 4x4 transform."""
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out
