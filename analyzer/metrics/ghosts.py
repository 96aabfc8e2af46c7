"""Double images: a crossfade that shows two objects, measured against the source's own level."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import Range, check_frames
from ...errors import InvalidArgumentError
from ._common import luma

_GHOST_SIDE = 96  # longer side of the luma frames the double-image measure compares
_GHOST_MOVING = 0.75  # the moving region: pixels whose temporal deviation is above this quantile


class DoubleImages:
    """The double-image measure against one source, its thumbnails computed once (see
    :func:`double_image`): ``of(frames)``, ``crossfades(first, second, weight)``, ``level()``."""

    def __init__(self, source: np.ndarray) -> None:
        source = check_frames(source, name="source", min_frames=2)
        self.shape = source.shape[1:3]
        h, w = self.shape
        s = min(1.0, _GHOST_SIDE / max(h, w))
        self.size = max(1, round(h * s)), max(1, round(w * s))
        g = luma(source, size=self.size)
        dev = g.std(axis=0)
        self.moving = dev >= np.quantile(dev, _GHOST_MOVING)
        #: the source's thumbnails over the moving region, ``(T, M)``
        self.rows = g[:, self.moving].astype(np.float64)
        self._norms = np.einsum("ij,ij->i", self.rows, self.rows)
        self.step = float(np.median(np.sqrt(np.mean(np.diff(self.rows, axis=0) ** 2, axis=1))))
        if self.step <= 0:
            raise InvalidArgumentError("source does not change from frame to frame (median frame difference is 0)")

    def of(self, frames: np.ndarray) -> np.ndarray:
        """The measure of each frame of ``frames`` (the source's frame size)."""
        frames = check_frames(frames, name="output")
        if frames.shape[1:3] != self.shape:
            raise InvalidArgumentError(
                f"double_image needs output and source of one frame size: {frames.shape[1:3]} vs {self.shape}"
            )
        return self._ratios(luma(frames, size=self.size)[:, self.moving].astype(np.float64))

    def crossfades(self, first: Any, second: Any, weight: Any) -> np.ndarray:
        """The measure of ``(1 - weight) * source[first] + weight * source[second]`` (arrays of one shape)."""
        a, b = np.asarray(first), np.asarray(second)
        w = np.asarray(weight, np.float64)
        if a.shape != b.shape or a.shape != w.shape:
            raise InvalidArgumentError(
                f"first, second and weight must have one shape, not {a.shape}, {b.shape}, {w.shape}"
            )
        t = len(self.rows)
        for name, idx in (("first", a), ("second", b)):
            if idx.size and (idx.dtype.kind not in "ui" or idx.min() < 0 or idx.max() >= t):
                raise InvalidArgumentError(f"{name} must be frame indices in 0..{t - 1}")
        if a.size and (not np.isfinite(w).all() or w.min() < 0 or w.max() > 1):
            raise InvalidArgumentError("weight must lie in [0, 1]")
        a, b, w = a.ravel(), b.ravel(), w.ravel()[:, None]
        return self._ratios((1 - w) * self.rows[a] + w * self.rows[b]).reshape(np.shape(first))

    def level(self, quantile: float = 0.9) -> float:
        """The ``quantile`` of the measure over the means of consecutive source frames."""
        q = Range(float, 0.0, 1.0).check("quantile", quantile)
        return float(np.quantile(self._ratios((self.rows[:-1] + self.rows[1:]) / 2), q))

    def _ratios(self, q: np.ndarray) -> np.ndarray:
        """RMS distance of each row of ``q`` to its nearest source row, over the median step."""
        out = np.empty(len(q))
        for i in range(0, len(q), 256):
            c = q[i : i + 256]
            d2 = np.einsum("ij,ij->i", c, c)[:, None] + self._norms[None, :] - 2.0 * (c @ self.rows.T)
            out[i : i + len(c)] = np.sqrt(np.maximum(d2.min(axis=1), 0.0) / self.rows.shape[1])
        return out / self.step


def double_image(output: np.ndarray, source: np.ndarray) -> np.ndarray:
    """Per output frame: how far it is from the nearest source frame, in the source's moving
    region, over the source's median frame step there.

    0 for a frame the source holds; about 0.5 for the mean of two consecutive source frames
    (the in-between a fractional speed shows, see :func:`double_image_level`); about 1 or more
    for a crossfade of two frames whose moving parts sit in different places (two
    half-transparent objects). Luma thumbnails (longer side 96 pixels); the moving region is
    the quarter of the pixels with the largest temporal standard deviation in the source.
    :class:`DoubleImages` keeps one source's thumbnails for many calls.

    Examples
    --------
    >>> clip = np.zeros((16, 8, 32), np.uint8)
    >>> for i in range(16):
    ...     clip[i, :, 4 + i : 12 + i] = 200              # a bar 8 pixels wide moving 1 pixel a frame
    >>> ghost = (clip[2].astype(float) + clip[10]) / 2    # frames 8 apart, crossfaded
    >>> round(float(double_image(ghost[None], clip)[0]), 2), double_image(clip[:3], clip).tolist()
    (1.5, [0.0, 0.0, 0.0])
    """
    return DoubleImages(source).of(output)


def double_image_level(source: np.ndarray, *, quantile: float = 0.9) -> float:
    """The source's own double-image level: the ``quantile`` of :func:`double_image` over the
    means of consecutive source frames (what playing the source between two frames shows).

    Examples
    --------
    >>> clip = np.zeros((16, 8, 32), np.uint8)
    >>> for i in range(16):
    ...     clip[i, :, 4 + i : 12 + i] = 200
    >>> round(double_image_level(clip), 2)
    0.5
    """
    return DoubleImages(source).level(quantile)


def crossfade_double_image(source: np.ndarray, first: Any, second: Any, weight: Any) -> np.ndarray:
    """:func:`double_image` of the crossfades ``(1 - weight) * source[first] + weight * source[second]``
    (index and weight arrays of one shape), computed on the thumbnails without forming the frames.

    Examples
    --------
    >>> clip = np.zeros((16, 8, 32), np.uint8)
    >>> for i in range(16):
    ...     clip[i, :, 4 + i : 12 + i] = 200
    >>> crossfade_double_image(clip, [3, 2], [4, 10], [0.5, 0.5]).round(2).tolist()
    [0.5, 1.5]
    """
    return DoubleImages(source).crossfades(first, second, weight)
