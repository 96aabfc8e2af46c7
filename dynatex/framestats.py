"""Statistics of a clip's frames that the analysis, the metrics and the player's loops share: the
step between frames (numpy alone, so the player may use it).

The median RMS difference of consecutive frames is the clip's typical frame step: the metrics
measure jumps against it (:func:`~dynatex.analyzer.metrics.temporal_discontinuity`), the tiles
analysis stores it (``median_frame_step``) and ``dynatex play --loop`` and ``dynatex export
--loop`` report a loop's wrap against it (:func:`~dynatex.player.loop.wrap_report`). Frames are
``(T, H, W, C)`` arrays, uint8 or floats on the 0..255 scale, converted to float32 a chunk at a
time so that long clips need little memory.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

#: frames converted to float at a time (bounds memory on long clips)
CHUNK = 32
#: weights of R, G and B in a frame's luma (ITU-R BT.601, the video codecs' own)
LUMA = np.array([0.299, 0.587, 0.114], np.float32)


def even_sample(length: int, n: int) -> np.ndarray:
    """Up to ``n`` indices of ``0 .. length - 1``, evenly spread, first and last included.

    >>> even_sample(10, 4).tolist(), even_sample(3, 8).tolist()
    ([0, 3, 6, 9], [0, 1, 2])
    """
    return np.unique(np.linspace(0, length - 1, min(n, length)).round().astype(int))


def float_chunks(frames: np.ndarray, start: int = 0, stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """``(first index, float32 frames)`` for the frames ``start:stop``, :data:`CHUNK` at a time."""
    stop = frames.shape[0] if stop is None else stop
    for i in range(start, stop, CHUNK):
        yield i, frames[i : min(i + CHUNK, stop)].astype(np.float32)


def step_rms(frames: np.ndarray, *, pairs: int | None = None) -> np.ndarray:
    """RMS difference (grey levels, over pixels and channels) between consecutive frames.

    Every pair ``(T-1,)``, or with ``pairs`` at most that many pairs spread evenly over the clip
    (a cost that does not grow with the clip's length).

    Examples
    --------
    >>> ramp = np.repeat(np.arange(0, 40, 2, dtype=np.uint8), 4).reshape(20, 2, 2, 1)
    >>> step_rms(ramp)[:3].tolist(), step_rms(ramp, pairs=4).tolist()
    ([2.0, 2.0, 2.0], [2.0, 2.0, 2.0, 2.0])
    """
    t = frames.shape[0]
    if pairs is not None and pairs < t - 1:
        idx = np.unique(np.linspace(0, t - 2, max(1, pairs)).round().astype(int))
        return np.concatenate([_rms(np.stack([frames[i], frames[i + 1]]).astype(np.float32)) for i in idx])
    out = np.empty(max(t - 1, 0), np.float64)
    prev = None
    for i, chunk in float_chunks(frames):
        first = i
        if prev is not None:
            chunk = np.concatenate([prev, chunk])
            first = i - 1
        out[first : first + len(chunk) - 1] = _rms(chunk)
        prev = chunk[-1:]
    return out


def median_step(frames: np.ndarray, *, pairs: int | None = None) -> float:
    """The clip's typical frame step: the median of :func:`step_rms` (``pairs`` as there).

    >>> ramp = np.repeat(np.arange(0, 40, 2, dtype=np.uint8), 4).reshape(20, 2, 2, 1)
    >>> median_step(ramp[::2])
    4.0
    """
    return float(np.median(step_rms(frames, pairs=pairs)))


def _rms(chunk: np.ndarray) -> np.ndarray:
    """RMS of each difference between consecutive frames of a float chunk, ``(len(chunk) - 1,)``."""
    d = np.diff(chunk, axis=0).reshape(chunk.shape[0] - 1, -1)
    return np.sqrt(np.einsum("ij,ij->i", d, d, dtype=np.float64) / d.shape[1])
