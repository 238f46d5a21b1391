"""Datasets, scans and the frame view pickle and work in spawned worker processes.

PyTorch's ``DataLoader(num_workers=N)`` pickles its dataset into each worker; with the spawn start
method (the default on macOS and Windows) nothing is inherited, so a dataset holding a lock or an
open descriptor fails there. The standard library's spawn pool stands in for the DataLoader here
(torch is not a test dependency: see README, "Using a dataset from PyTorch").
"""

from __future__ import annotations

import multiprocessing
import pickle
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from psg_data.loaders import FrameView, open_dataset


def _records_in_child(view: FrameView, indices: list[int]) -> tuple[list[dict], int]:  # type: ignore[type-arg]
    """Runs in a spawned worker: the view arrived pickled, with no file open."""
    assert view.dataset._images._fds == {}
    out = [view[i] for i in indices]
    return out, len(view.dataset._images._fds)


def _same(a: dict, b: dict) -> bool:  # type: ignore[type-arg]
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]), k
        else:
            assert a[k] == b[k], k
    return True


def test_frame_view_indexes_every_frame(make_dataset: Callable[..., Path]) -> None:
    ds = open_dataset(make_dataset(scans=3, frames=4))
    view = ds.frame_view()
    assert len(view) == 12
    r = view[5]
    assert (r["scan_id"], r["frame_index"]) == ("scan_001", 1)
    fr = ds.scan("scan_001").frame(1)
    assert np.array_equal(r["color"], fr.color) and r["color"].dtype == np.uint8 and r["color"].shape == (24, 32, 3)
    assert np.array_equal(r["depth_m"], fr.depth_m) and r["depth_m"].dtype == np.float32
    assert np.array_equal(r["T_world_camera"], fr.T_world_camera) and r["T_world_camera"].shape == (4, 4)
    assert np.array_equal(r["K"], fr.camera.K) and r["stamp_ns"] == fr.stamp_ns == int(ds.scan("scan_001").stamps_ns[1])
    assert r["image_size"].tolist() == [32, 24] and r["camera_id"] == "d435"
    assert _same(view[-1], view[11]) and view[11]["scan_id"] == "scan_002"
    with pytest.raises(IndexError, match="out of range"):
        view[12]
    sub = ds.frame_view(["scan_002", "scan_000"], depth=False)
    assert [(x["scan_id"], x["frame_index"]) for x in sub] == [("scan_002", i) for i in range(4)] + \
        [("scan_000", i) for i in range(4)]
    assert sub[0]["depth_m"].shape == (0, 0)
    with pytest.raises(KeyError, match="no scan"):
        ds.frame_view(["nope"])


def test_dataset_and_scan_pickle_without_open_files(make_dataset: Callable[..., Path]) -> None:
    ds = open_dataset(make_dataset())
    scan = ds.scans[1]
    before = scan.frame(2)
    assert ds._images._fds  # an archive is open now
    blob = pickle.dumps(ds)
    assert len(blob) < 2000, "no cached table travels with a pickled dataset"
    ds2 = pickle.loads(blob)
    assert ds2._images._fds == {} and ds2._arrow == {}
    assert ds2.scan_ids == ds.scan_ids and ds2.info == ds.info
    scan2 = pickle.loads(pickle.dumps(scan))
    after = scan2.frame(2)
    assert np.array_equal(before.color, after.color) and np.array_equal(before.depth_m, after.depth_m)
    assert scan2.dataset._images._fds  # reopened on first read


def test_frame_view_in_a_spawn_pool_of_two_workers(make_dataset: Callable[..., Path]) -> None:
    """What ``DataLoader(view, num_workers=2, multiprocessing_context="spawn")`` does: each worker
    gets the pickled view and reads its share of frames; the records equal the parent's."""
    ds = open_dataset(make_dataset(scans=3, frames=4))
    view = ds.frame_view()
    view[0]  # the parent has an archive open: it must not travel
    shares = [list(range(0, len(view), 2)), list(range(1, len(view), 2))]
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        got = pool.starmap(_records_in_child, [(view, s) for s in shares])
    for share, (records, n_open) in zip(shares, got):
        assert n_open >= 1  # the worker opened the archives itself
        for i, rec in zip(share, records):
            assert _same(rec, view[i])
    assert sum(len(r) for r, _ in got) == 12
