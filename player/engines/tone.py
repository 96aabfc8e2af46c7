"""The map from a projection model's tone values back to levels (the ``tone`` part,
:mod:`dynatex.tiledb.tone`), shared by the projection engine's numpy reference and its kernel.

A model learned on Gaussianised values projects to tone values; each value ``y`` of channel
``c`` becomes the level ``table[c, bin]``, ``bin = floor((y - lo[c]) * scale[c])`` clamped to
``0 .. BINS - 1`` (the format's lookup, ``tiledb/FORMAT.md``). Values beyond the ends saturate to
levels 0 and 255, as a projection's values beyond 0..255 do. The bin index is computed in
float32 by both backends; the stored table's steps are at least a bin wide, so a value's bin,
off by one where the two backends' sums differ in their last bit, gives a level at most one
apart (the projection's tolerance).
"""

from __future__ import annotations

import numpy as np

from ...tiledb.tone import BINS, ToneModel, lookup


class ToneLookup:
    """``lo``, ``scale`` (float32, one per channel) and ``table`` ``(channels, BINS)`` uint8
    (:func:`~dynatex.tiledb.tone.lookup`) of ``tone``; :meth:`levels` maps tone values to levels.

    >>> fwd = np.linspace(-40.0, 300.0, 256, dtype=np.float32)[None]
    >>> t = ToneLookup(ToneModel(fwd))
    >>> t.levels(np.array([[-100.0, -40.0, 300.0, 130.0]], np.float32)).tolist()
    [[0.0, 0.0, 255.0, 128.0]]
    """

    def __init__(self, tone: ToneModel) -> None:
        fwd = np.asarray(tone.forward, np.float64)
        self.channels = fwd.shape[0]
        self.lo = fwd[:, 0].astype(np.float32)
        self.scale = (BINS / (fwd[:, -1] - fwd[:, 0])).astype(np.float32)
        self.table = lookup(tone)
        self._flat = self.table.reshape(-1).astype(np.float32)
        self._rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._index: np.ndarray | None = None

    def _per_value(self, values: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``lo``, ``scale`` and each channel's table offset repeated along a row of ``values``
        interleaved values: numpy combines rows of one length far faster than it broadcasts a
        trailing axis of 3."""
        if self._rows is None or len(self._rows[0]) != values:
            pixels = values // self.channels
            offset = np.arange(self.channels, dtype=np.int32) * BINS
            self._rows = tuple(np.tile(a, pixels) for a in (self.lo, self.scale, offset))
        return self._rows

    def levels(self, values: np.ndarray) -> np.ndarray:
        """Tone values ``(k, P)`` float32 (``P`` interleaved values of ``channels`` channels a row)
        replaced by their levels, in place; returns ``values``."""
        lo, scale, offset = self._per_value(values.shape[-1])
        values -= lo
        values *= scale
        np.fmax(values, 0, out=values)  # fmax/fmin as OpenCL's clamp: NaN (no valid map makes one) -> 0
        np.fmin(values, BINS - 1, out=values)
        if self._index is None or self._index.shape != values.shape:
            self._index = np.empty(values.shape, np.int32)
        np.copyto(self._index, values, casting="unsafe")  # truncation, as astype
        self._index += offset
        return np.take(self._flat, self._index, out=values)
