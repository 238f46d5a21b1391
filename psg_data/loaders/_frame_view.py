"""A frame-indexed, picklable view of a dataset for training loops (``torch.utils.data.Dataset`` style).

``len(view)`` frames over the chosen scans (in start-time order, frames in index order) and
``view[i]`` a :class:`FrameRecord`: a plain dict of numpy arrays and scalars, which
``torch.utils.data.default_collate`` batches as it is. The view holds no open file: pickled into a
worker process (``DataLoader(num_workers=N)``, any start method), it reopens the dataset's image
archives lazily there.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, TypedDict

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.loaders._dataset import Dataset

__all__ = ["FrameRecord", "FrameView"]


class FrameRecord(TypedDict):
    """One frame as numpy arrays and metadata.

    Keys:
        color: (H, W, 3) uint8 RGB (``(0, 0, 3)`` if the view was made with ``color=False``).
        depth_m: (H, W) float32 depth along the optical axis, metres, 0 where invalid
            (``(0, 0)`` with ``depth=False``).
        T_world_camera: (4, 4) float64 camera-to-world pose, OpenCV camera axes, metres.
        K: (3, 3) float64 pinhole intrinsics of the colour camera, pixels.
        distortion: (k,) float64 distortion coefficients (model in ``distortion_model``).
        image_size: (2,) int64 ``(width, height)`` in pixels.
        stamp_ns: capture time, int UTC nanoseconds.
        scan_id: scan of the frame.
        frame_index: frame index within the scan.
        camera_id: camera of the frame.
        distortion_model: ``none``, ``plumb_bob``, ...
    """

    color: NDArray[np.uint8]
    depth_m: NDArray[np.float32]
    T_world_camera: NDArray[np.float64]
    K: NDArray[np.float64]
    distortion: NDArray[np.float64]
    image_size: NDArray[np.int64]
    stamp_ns: int
    scan_id: str
    frame_index: int
    camera_id: str
    distortion_model: str


class FrameView(Sequence[FrameRecord]):
    """Every frame of some scans of a dataset, by one flat index.

    Args:
        dataset: an open :class:`~psg_data.loaders.Dataset`.
        scan_ids: scans to include (default: all), in the order given.
        color: decode colour images.
        depth: decode depth images.

    Raises:
        KeyError: an unknown scan id.
    """

    def __init__(self, dataset: Dataset, scan_ids: Sequence[str] | None = None, *, color: bool = True,
                 depth: bool = True) -> None:
        self.dataset = dataset
        self.scan_ids = list(dataset.scan_ids if scan_ids is None else scan_ids)
        for s in self.scan_ids:
            dataset.scan(s)  # KeyError naming the scans there are
        self.color, self.depth = color, depth
        sizes = np.array([len(dataset.scan(s)) for s in self.scan_ids], dtype=np.int64)
        self._starts = np.concatenate([[0], np.cumsum(sizes)])

    def __len__(self) -> int:
        return int(self._starts[-1])

    def locate(self, i: int) -> tuple[str, int]:
        """``(scan_id, index within the scan)`` of flat frame ``i`` (negative counts from the end)."""
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"frame {i} out of range for a view of {n} frames")
        i %= n
        k = int(np.searchsorted(self._starts, i, side="right")) - 1
        return self.scan_ids[k], i - int(self._starts[k])

    def __getitem__(self, i: int) -> FrameRecord:  # type: ignore[override]
        if not isinstance(i, (int, np.integer)):
            raise TypeError(f"frame index must be an integer, got {type(i).__name__}")
        scan_id, j = self.locate(int(i))
        fr = self.dataset.scan(scan_id).frame(j, color=self.color, depth=self.depth)
        cam = fr.camera
        return FrameRecord(
            color=fr.color, depth_m=fr.depth_m, T_world_camera=fr.T_world_camera, K=cam.K,
            distortion=np.asarray(cam.distortion_coeffs, dtype=np.float64),
            image_size=np.array([cam.width, cam.height], dtype=np.int64), stamp_ns=fr.stamp_ns,
            scan_id=fr.scan_id, frame_index=fr.index, camera_id=cam.camera_id,
            distortion_model=cam.distortion_model)

    def __iter__(self) -> Iterator[FrameRecord]:
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        return f"FrameView({str(self.dataset.root)!r}, scans={len(self.scan_ids)}, frames={len(self)})"
