"""Stored source frames (the ``frames`` dataset) that the gather-based modes play from."""

from __future__ import annotations

import h5py
import numpy as np

from ..errors import InvalidArgumentError
from ._check import Checker
from .source import SourceInfo


def write(parent: h5py.Group, name: str, frames: np.ndarray) -> h5py.Dataset:
    """Store ``(T, H, W, C)`` uint8 frames chunked one frame per chunk, LZF-compressed."""
    frames = np.asarray(frames)
    if frames.dtype != np.uint8 or frames.ndim != 4:
        raise InvalidArgumentError(f"frames must be a (T, H, W, C) uint8 array, got {frames.dtype} {frames.shape}")
    return parent.create_dataset(name, data=frames, chunks=(1, *frames.shape[1:]), compression="lzf", shuffle=False)


class FrameStore:
    """Lazy, validated view of stored frames: ``store[i]`` reads one frame from disk.

    ``store.read()`` loads them all (``len(store) * H * W * C`` bytes).
    """

    def __init__(self, dataset: h5py.Dataset, check: Checker) -> None:
        self._ds = dataset
        self._check = check
        self.shape: tuple[int, int, int, int] = tuple(dataset.shape)  # type: ignore[assignment]

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape))

    def __getitem__(self, index):
        try:
            return self._ds[index]
        except (OSError, RuntimeError) as exc:
            self._check.fail(self._ds.name, f"data cannot be read, the file may be corrupt ({exc})")

    def read(self) -> np.ndarray:
        """Every frame, once the bound of the database allows their bytes."""
        self._check.admit(self._ds.name, self.nbytes, "every stored frame")
        return self[()]


def read(
    parent: h5py.Group,
    name: str,
    check: Checker,
    source: SourceInfo,
    *,
    frame_shape: tuple[int, int, int] | None = None,
) -> FrameStore:
    """Open ``parent/name`` as a :class:`FrameStore` of the source's ``n_frames`` frames of
    ``frame_shape`` (default: the source's); the methods index them by the source's count."""
    shape = frame_shape or source.frame_shape
    ds = check.dataset(parent, name, kind="u", shape=(range(2**63), *shape), read=False)
    if ds.dtype != np.uint8:
        check.fail(ds.name, f"dtype {ds.dtype} is not uint8")
    if ds.shape[0] < 1:
        check.fail(ds.name, "holds no frames")
    if ds.shape[0] != source.n_frames:
        check.fail(ds.name, f"holds {ds.shape[0]} frames, the source says {source.n_frames}")
    return FrameStore(ds, check)
