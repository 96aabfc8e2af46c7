"""Double images: a crossfade that shows two objects, measured against the source's own level."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import Range, check_frames
from ...errors import InvalidArgumentError
from ._common import luma
from .memo import remembered

_GHOST_SIDE = 96  # longer side of the luma frames the double-image measure compares
_GHOST_MOVING = 0.75  # the moving region: pixels whose temporal deviation is above this quantile
_LOCAL_SIDE = 192  # longer side of the luma frames local_novelty compares
_LOCAL_PATCH = 8  # side of its patches
_LOCAL_REACH = 4  # it searches source patches this many pixels either way (in steps of 2)
_LOCAL_FRAMES = 60  # output frames it measures at most (evenly spaced)
_LOCAL_FLOOR = 0.25  # least reference level, in frame steps (a clip whose halves repeat each other)


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


def local_novelty(output: np.ndarray, source: np.ndarray) -> float | None:
    """How far the output's local structure lies from anything the source shows at that place,
    over the same figure for the source's second half against its first half (about 1 for an
    unseen stretch of the same texture; 0 for the source's own frames).

    Per 8x8 patch of the moving region (luma, longer side 192 pixels; the quarter of the patches
    with the largest temporal deviation): the RMS distance to the
    nearest source patch at that place, shifted up to 4 pixels either way, over the source's
    median frame step; the median over patches, then over up to 60 evenly spaced output frames.
    A Gaussian model that mixes positions the source never shows together (ghosted flag stripes)
    makes patches no source frame has; a crossfade of two frames of a texture whose patches
    come in a continuum of contrasts (water, fire) stays near it. None when no patch fits the
    frame (under 16 pixels). The reference is at least 0.25 frame steps.

    Examples
    --------
    >>> x = np.arange(64)
    >>> stripes = np.where((x[None, :] - np.arange(48)[:, None]) % 16 < 8, 220, 30)
    >>> clip = np.repeat(stripes[:, None, :], 32, axis=1).astype(np.uint8)   # stripes moving 1 px a frame
    >>> local_novelty(clip, clip)
    0.0
    >>> ghost = ((clip.astype(float) + np.roll(clip, 4, axis=2)) / 2).astype(np.uint8)
    >>> round(local_novelty(ghost, clip), 1)                                   # stripes at two places
    4.0
    """
    source = check_frames(source, name="source", min_frames=4)
    output = check_frames(output, name="output")
    if output.shape[1:3] != source.shape[1:3]:
        raise InvalidArgumentError(
            f"local_novelty needs output and source of one frame size: {output.shape[1:3]} vs {source.shape[1:3]}"
        )
    h, w = source.shape[1:3]
    s = min(1.0, _LOCAL_SIDE / max(h, w))
    size = max(1, round(h * s)), max(1, round(w * s))
    g = luma(source, size=size)
    reference = _novelty_reference(g)
    if reference is None:
        return None
    cells, step, level = reference
    o = luma(output[:: max(1, -(-len(output) // _LOCAL_FRAMES))], size=size)
    p = _LOCAL_PATCH
    out = np.empty((len(o), len(cells)))
    for k, (y, x) in enumerate(cells):
        out[:, k] = _nearest(o[:, y : y + p, x : x + p].reshape(len(o), -1), _bank(g, y, x).reshape(-1, p * p))
    return float(np.median(np.median(out, axis=1))) / step / level


@remembered
def _novelty_reference(g: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """:func:`local_novelty`'s source side from the source's luma ``g``: the moving patches' corners
    ``(k, 2)``, the median frame step over them, and the source's own level (its second half's
    patches against its first half's, in frame steps); None when no patch fits the frame."""
    p, r = _LOCAL_PATCH, _LOCAL_REACH
    size = g.shape[1:]
    grid = [(y, x) for y in range(r, size[0] - p - r + 1, p) for x in range(r, size[1] - p - r + 1, p)]
    if not grid:
        return None
    dev = g.std(axis=0)
    patch_dev = np.array([dev[y : y + p, x : x + p].mean() for y, x in grid])
    cells = [c for c, d in zip(grid, patch_dev) if d >= np.quantile(patch_dev, _GHOST_MOVING)]
    moving = np.zeros(size, bool)
    for y, x in cells:
        moving[y : y + p, x : x + p] = True
    step = float(np.median(np.sqrt(np.mean(np.diff(g[:, moving], axis=0) ** 2, axis=1))))
    if step <= 0:
        raise InvalidArgumentError("source does not change from frame to frame (median frame difference is 0)")
    half = len(g) // 2
    later = g[half:][:: max(1, -(-(len(g) - half) // _LOCAL_FRAMES))]
    ref = np.empty((len(later), len(cells)))
    for k, (y, x) in enumerate(cells):
        patches = later[:, y : y + p, x : x + p].reshape(len(later), -1)
        ref[:, k] = _nearest(patches, _bank(g, y, x)[:half].reshape(-1, p * p))
    level = max(float(np.median(np.median(ref, axis=1))) / step, _LOCAL_FLOOR)
    return np.array(cells, np.intp).reshape(-1, 2), step, level


def _bank(g: np.ndarray, y: int, x: int) -> np.ndarray:
    """The source patches at ``(y, x)`` shifted up to the reach either way: ``(T, shifts, p * p)``."""
    p, r = _LOCAL_PATCH, _LOCAL_REACH
    shifts = [(dy, dx) for dy in range(-r, r + 1, 2) for dx in range(-r, r + 1, 2)]
    return np.stack([g[:, y + dy : y + dy + p, x + dx : x + dx + p].reshape(len(g), -1) for dy, dx in shifts], 1)


def _nearest(q: np.ndarray, bank: np.ndarray) -> np.ndarray:
    """RMS distance of each row of ``q`` to its nearest row of ``bank``."""
    q, bank = q.astype(np.float64), bank.astype(np.float64)
    d2 = np.einsum("ij,ij->i", q, q)[:, None] + np.einsum("ij,ij->i", bank, bank)[None, :] - 2.0 * (q @ bank.T)
    return np.sqrt(np.maximum(d2.min(axis=1), 0.0) / q.shape[1])


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
