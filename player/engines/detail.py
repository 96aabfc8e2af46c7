"""The detail engine: adds a model's fine detail to a projected frame and holds every pixel to
the source's colour range (the ``detail`` part of ``lds`` and ``mixture``, :mod:`dynatex.tiledb.detail`).

Per frame ``out = clamp(round(src + gain * (w0 * V[l0] + w1 * V[l1])), low, high)`` (or
``clamp(src, low, high)`` where that colour is not in the source's colour set), where
``V[l]`` is the stored noise volume read at layer ``l``'s frame and offset (it wraps in y and
x). Two layers cross-fade with weights ``sin`` and ``cos`` of the same phase (squares sum to
one, so the detail keeps its variance), each reborn at random offsets where its weight is 0:
the volume's own spatio-temporal spectrum moves the detail, and no loop of the volume ever
shows. The schedule is a function of the seed and the frame index alone (nothing to save).

OpenCL: the projection kernel adds it in the same pass as it projects (:mod:`.projection`,
``kernels/projection.cl``; one frame a pass as k), to the projected uint8 values, bit-exact
with the numpy reference :class:`DetailReference` (the kernel turns contraction off there).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ...tiledb.detail import DetailModel
from ..pixels import pixel_format


def layers(model_frames: int, shape: tuple[int, int], seed: int, frame: int, amount: float = 1.0):
    """The two layers of frame ``frame``: ``((t0, oy0, ox0, w0), (t1, oy1, ox1, w1))``.

    A layer lives ``L`` (the volume's length) frames, playing ``L`` consecutive volume frames
    from a random start and offset; layer 1 is half a life behind layer 0. ``amount`` scales
    both weights.

    >>> (a, b) = layers(32, (64, 64), 0, 5)
    >>> round(a[3] ** 2 + b[3] ** 2, 6)
    1.0
    """
    life = model_frames
    out = []
    for k in range(2):
        n_life, age = divmod(frame + k * (life // 2), life)
        # a clock run backwards (negative speed) reaches negative lives: wrapped to draw a seed
        t0, oy, ox = _birth(seed, k, n_life & 0xFFFFFFFFFFFFFFFF, life, shape[0], shape[1])
        w = math.sin(math.pi * (age + 0.5) / life)
        out.append(((t0 + age) % life, oy, ox, float(np.float32(amount * w))))
    return tuple(out)


@functools.lru_cache(maxsize=64)
def _birth(seed: int, k: int, n_life: int, life: int, vh: int, vw: int) -> tuple[int, int, int]:
    """Start frame and offset of layer ``k``'s life ``n_life`` (drawn once per life, then cached)."""
    rng = np.random.default_rng([seed & 0xFFFFFFFFFFFFFFFF, 0xD7, k, n_life])
    t0, oy, ox = (int(v) for v in rng.integers(0, (life, vh, vw)))
    return t0, oy, ox


class Detail:
    """Adds a :class:`DetailModel` to frames of ``shape`` ``(H, W, bytes)`` in ``format``."""

    backend = ""

    def __init__(self, model: DetailModel, *, shape: tuple[int, int, int], channels: int, format: str = "RGB") -> None:
        self.format = pixel_format(format)
        self.shape = tuple(shape)
        self.channels = channels
        self.volume = np.ascontiguousarray(model.volume)
        self.frames, self.vh, self.vw = self.volume.shape[:3]
        self.gain = np.ascontiguousarray(model.gain, np.float32)
        self.low = np.ascontiguousarray(model.low)
        self.high = np.ascontiguousarray(model.high)
        self.colours = np.ascontiguousarray(model.colours, np.uint8)

    @property
    def bytes_per_frame(self) -> int:
        """What a frame reads beyond the projected frame: gain, colour range, two volume reads (the
        colour set, 32 KiB, stays in cache)."""
        h, w = self.shape[:2]
        return int(h * w * (4 + 4 * self.channels))

    def layers(self, seed: int, frame: int, amount: float):
        """:func:`layers` for this volume."""
        return layers(self.frames, (self.vh, self.vw), seed, frame, amount)


def colour_bins(frames: np.ndarray, rgb: tuple[int, int, int] = (0, 1, 2)) -> np.ndarray:
    """Each pixel's colour bin ``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)`` (uint16) of
    ``frames`` (..., bytes) uint8 whose r, g, b are the bytes ``rgb``.

    >>> colour_bins(np.array([[8, 16, 255]], np.uint8)).tolist()
    [1119]
    """
    q = frames >> 3
    bins = np.left_shift(q[..., rgb[0]], 10, dtype=np.uint16)
    bins |= np.left_shift(q[..., rgb[1]], 5, dtype=np.uint16)
    bins |= q[..., rgb[2]]
    return bins


class DetailReference(Detail):
    """The numpy reference, in float32 in the kernel's order of operations."""

    backend = "numpy"

    def __init__(self, model: DetailModel, **kwargs) -> None:
        super().__init__(model, **kwargs)
        self._outside = self.colours == 0
        # once per value: a product with a broadcast last axis of 1 is several times slower
        self._gain = np.ascontiguousarray(np.repeat(self.gain[..., None], self.channels, axis=2))

    def _layer(self, t: int, oy: int, ox: int) -> np.ndarray:
        """Volume frame ``t`` read at offset ``(oy, ox)``, wrapping: an (H, W, channels) int8 view."""
        h, w = self.shape[:2]
        rows = self.volume[t].take((np.arange(h) + oy) % self.vh, axis=0)
        reps = -(-(ox + w) // self.vw)
        return (np.tile(rows, (1, reps, 1)) if reps > 1 else rows)[:, ox : ox + w]

    def apply(
        self, frame: np.ndarray, layers: tuple, out: np.ndarray | None = None, projected: np.ndarray | None = None
    ) -> np.ndarray:
        """``frame`` (H, W, bytes) uint8 in the output format with the detail added, into ``out``
        (``frame`` itself when None); ``projected``: the frame's values as (H, W, channels)
        float32 integers in 0..255, read instead of ``frame`` (which is then written alone)."""
        out = frame if out is None else out
        at = self.format.rgb
        rgb_in_place = self.channels == 3 and self.format.name == "RGB"
        if projected is None:
            projected = frame if rgb_in_place else frame[..., list(at[: self.channels])]
        (t0, oy0, ox0, w0), (t1, oy1, ox1, w1) = layers
        val = np.multiply(self._layer(t0, oy0, ox0), np.float32(w0), dtype=np.float32)
        val += np.multiply(self._layer(t1, oy1, ox1), np.float32(w1), dtype=np.float32)
        val *= self._gain
        val += projected
        np.rint(val, out=val)
        np.clip(val, 0, 255, out=val)
        u = val.astype(np.uint8)
        np.maximum(u, self.low, out=u)  # np.clip with array bounds is an order of magnitude slower
        np.minimum(u, self.high, out=u)
        outside = self._outside.take(colour_bins(u, (0, 1, 2) if self.channels == 3 else (0, 0, 0)))
        if outside.any():
            plain = projected[outside]  # the projected values of those pixels, uint8 or float32 integers
            u[outside] = np.clip(plain, self.low[outside], self.high[outside])
        if rgb_in_place:
            out[...] = u
        elif self.channels == 3:
            for c in range(3):
                out[..., at[c]] = u[..., c]
        else:
            for a in at:
                out[..., a] = u[..., 0]
        if self.format.alpha is not None:
            out[..., self.format.alpha] = 255
        return out
