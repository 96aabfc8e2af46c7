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
``kernels/lds.cl``), to the projected uint8 values, bit-exact with the numpy reference
:class:`DetailReference` (the kernel turns contraction off there).
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


class DetailReference(Detail):
    """The numpy reference, in float32 in the kernel's order of operations."""

    backend = "numpy"

    def apply(self, frame: np.ndarray, layers: tuple, out: np.ndarray | None = None) -> np.ndarray:
        """``frame`` (H, W, bytes) uint8 in the output format with the detail added, into ``out``
        (``frame`` itself when None)."""
        out = frame if out is None else out
        h, w = self.shape[:2]
        noise = np.empty((h, w, self.channels), np.float32)
        for k, (t, oy, ox, wt) in enumerate(layers):
            rows = (np.arange(h) + oy) % self.vh
            cols = (np.arange(w) + ox) % self.vw
            v = self.volume[t].take(rows, axis=0).take(cols, axis=1).astype(np.float32)
            v *= np.float32(wt)
            if k == 0:
                noise[...] = v
            else:
                noise += v
        noise *= self.gain[..., None]
        at = self.format.rgb
        rgb_in_place = self.channels == 3 and self.format.name == "RGB"
        val = frame.astype(np.float32) if rgb_in_place else frame[..., list(at[: self.channels])].astype(np.float32)
        val += noise
        np.rint(val, out=val)
        np.clip(val, self.low, self.high, out=val)  # within 0..255 already: low and high are uint8
        val = val.astype(np.uint8)
        q = (val >> 3).astype(np.int32)
        r, g, b = (0, 1, 2) if self.channels == 3 else (0, 0, 0)
        bins = (q[..., r] << 10) | (q[..., g] << 5) | q[..., b]
        outside = self.colours[bins] == 0
        if outside.any():
            plain = frame[..., list(at[: self.channels])][outside]
            val[outside] = np.clip(plain, self.low[outside], self.high[outside])
        if rgb_in_place:
            out[...] = val
        elif self.channels == 3:
            for c in range(3):
                out[..., at[c]] = val[..., c]
        else:
            for a in at:
                out[..., a] = val[..., 0]
        if self.format.alpha is not None:
            out[..., self.format.alpha] = 255
        return out
