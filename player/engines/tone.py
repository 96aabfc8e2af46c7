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

    >>> fwd = np.tile(np.linspace(-40.0, 300.0, 256, dtype=np.float32), (1, 1))
    >>> t = ToneLookup(ToneModel(fwd))
    >>> t.levels(np.array([[-100.0], [-40.0], [300.0], [130.0]], np.float32)).ravel().tolist()
    [0.0, 0.0, 255.0, 128.0]
    """

    def __init__(self, tone: ToneModel) -> None:
        fwd = np.asarray(tone.forward, np.float64)
        self.channels = fwd.shape[0]
        self.lo = fwd[:, 0].astype(np.float32)
        self.scale = (BINS / (fwd[:, -1] - fwd[:, 0])).astype(np.float32)
        self.table = lookup(tone)
        self._flat = self.table.reshape(-1).astype(np.float32)
        self._offset = np.arange(self.channels, dtype=np.int32) * BINS

    def levels(self, values: np.ndarray) -> np.ndarray:
        """The levels, as float32, of tone values ``(..., channels)`` float32 (a new array)."""
        t = values - self.lo
        t *= self.scale
        np.clip(t, 0, BINS - 1, out=t)
        index = t.astype(np.int32)
        index += self._offset
        return self._flat[index]
