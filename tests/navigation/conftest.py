"""Fixtures of the navigation tests: hand-built grids and a small generated dataset."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from psg_data.navigation import NavigationEnv, OccupancyGrid, Query
from psg_data.schemas import Box, CameraIntrinsics, Door, ObjectInfo, Receptacle, Room
from psg_data.writers import DatasetWriter

T0_S = 1_700_000_000.0


class ScriptedFilter:
    """An EdgeFilter whose belief is a step function of time; records its updates."""

    def __init__(self, edge: tuple[str, str], before: float, after: float | None = None, switch_s: float = np.inf):
        self.edge = edge
        self.before, self.after, self.switch_s = before, before if after is None else after, switch_s
        self.updates: list[tuple[float, int]] = []
        self._last: float | None = None

    @property
    def last_t_s(self) -> float | None:
        return self._last

    def update(self, t_s: float, y: int) -> None:
        self.updates.append((float(t_s), int(y)))
        self._last = float(t_s)

    def update_many(self, t_s: Any, y: Any) -> None:
        for a, b in zip(np.asarray(t_s).reshape(-1), np.asarray(y).reshape(-1)):
            self.update(float(a), int(b))

    def predict(self, t_s: Any) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        return np.where(t < self.switch_s, self.before, self.after).astype(np.float64)

    def get_state(self) -> dict[str, Any]:
        return {}


def corridor_grid() -> OccupancyGrid:
    """5 x 30 cells of 1 m, robot radius 0; receptacle A at (2, 0), B at (2, 29), C at (0, 15)."""
    H, W = 5, 30
    obs = np.zeros((H, W), dtype=bool)
    recs = {}
    for name, (i, j) in {"A": (2, 0), "B": (2, 29), "C": (0, 15)}.items():
        m = np.zeros((H, W), dtype=bool)
        m[i, j] = True
        recs[name] = m
        obs |= m
    return OccupancyGrid(obs, np.array([0.0, 0.0]), 1.0, 0.0, {}, recs, "test")


def door_grid() -> OccupancyGrid:
    """7 x 21 cells of 1 m: a wall in column 10 (rows 0-5) with door 'd' at row 1 and a gap at row 6;
    receptacle T at (1, 18) and S at (1, 0)."""
    H, W = 7, 21
    obs = np.zeros((H, W), dtype=bool)
    obs[0:6, 10] = True
    door = np.zeros((H, W), dtype=bool)
    door[1, 10] = True
    obs[1, 10] = False
    recs = {}
    for name, (i, j) in {"T": (1, 18), "S": (1, 0)}.items():
        m = np.zeros((H, W), dtype=bool)
        m[i, j] = True
        recs[name] = m
        obs |= m
    return OccupancyGrid(obs, np.array([0.0, 0.0]), 1.0, 0.0, {"d": door}, recs, "test")


def make_query(grid: OccupancyGrid, start: tuple[int, int], gt: str | None, *, obj: str = "obj",
               doors: dict[str, bool] | None = None, category: str | None = None, t_s: float = T0_S + 3600.0,
               qid: int = 0) -> Query:
    xy = grid.cell_to_world(start)
    cat = category or ("absent" if gt is None else "dynamic")
    return Query(qid, 0, obj, t_s, start, (float(xy[0]), float(xy[1])), cat, gt, None, dict(doors or {}))


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def write_nav_dataset(root: Path, *, n_scans: int = 24, seed: int = 0) -> Path:
    """Two 4 x 3 m rooms side by side (x in [0, 4] and [4, 8]) joined by one door; four receptacles;
    objects: 'mug' (static on k_table), 'book' (moves between k_shelf and o_desk), 'keys' (often
    absent); door closed in every third scan; 2/3 of the scans 'train', one scan every 2 hours."""
    rng = np.random.default_rng(seed)
    cam = CameraIntrinsics("cam", 8, 6, 7.0, 7.0, 3.5, 2.5)
    rooms = [Room("kitchen", "Kitchen", np.array([[0, 0], [4, 0], [4, 3], [0, 3.0]])),
             Room("office", "Office", np.array([[4, 0], [8, 0], [8, 3], [4, 3.0]]))]
    recs = [
        Receptacle("k_table", "table", "kitchen", Box(np.array([1.0, 0.5, 0.4]), np.array([1.0, 0.6, 0.8])), "table"),
        Receptacle("k_shelf", "shelf", "kitchen", Box(np.array([1.0, 2.6, 0.9]), np.array([0.8, 0.4, 1.8]),
                                                      _rot_z(0.0)), "shelf"),
        Receptacle("o_desk", "desk", "office", Box(np.array([7.0, 0.5, 0.4]), np.array([1.0, 0.6, 0.8])), "desk"),
        Receptacle("o_bench", "bench", "office", Box(np.array([6.5, 2.6, 0.4]), np.array([1.2, 0.4, 0.8]),
                                                     _rot_z(0.2)), "bench"),
    ]
    door = Door("door1", "kitchen-office", "kitchen", "office", Box(np.array([4.0, 1.5, 1.0]),
                                                                    np.array([0.14, 0.9, 2.0])))
    with DatasetWriter(root, name="navtest", timezone="UTC") as w:
        w.add_camera(cam)
        w.set_rooms(rooms)
        w.set_receptacles(recs)
        w.set_doors([door])
        w.set_objects([ObjectInfo(o, o) for o in ("mug", "book", "keys")])
        drows, srows = [], []
        n_train = int(round(n_scans * 2 / 3))
        for s in range(n_scans):
            sid = f"scan_{s:03d}"
            with w.scan(sid, split="train" if s < n_train else "test") as sw:
                sw.add_frame(int((T0_S + s * 7200) * 1e9), np.eye(4), rng.integers(0, 255, (6, 8, 3), dtype=np.uint8),
                             rng.integers(500, 3000, (6, 8), dtype=np.uint16), "cam")
            drows.append({"scan_id": sid, "door_id": "door1", "state": "closed" if s % 3 == 2 else "open"})
            srows.append({"scan_id": sid, "object_id": "mug", "receptacle_id": "k_table"})
            srows.append({"scan_id": sid, "object_id": "book",
                          "receptacle_id": "k_shelf" if (s // 2) % 2 == 0 else "o_desk"})
            srows.append({"scan_id": sid, "object_id": "keys",
                          "receptacle_id": None if s % 4 in (1, 2) else "o_bench"})
        w.set_table("door_states", drows)
        w.set_table("schedule", srows)
    return root


@pytest.fixture
def nav_dataset(tmp_path: Path) -> Path:
    return write_nav_dataset(tmp_path / "navds")


@pytest.fixture
def nav_env(nav_dataset: Path) -> NavigationEnv:
    return NavigationEnv.from_dataset(nav_dataset, resolution_m=0.05, robot_radius_m=0.2)


@pytest.fixture
def scripted() -> Callable[..., ScriptedFilter]:
    return ScriptedFilter
