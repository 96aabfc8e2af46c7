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

#: Values :meth:`ToneLookup.levels` maps at once (a multiple of 3)
CHUNK = 3 << 16


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
        pixels = CHUNK // self.channels
        offset = np.arange(self.channels, dtype=np.intp) * BINS
        # lo, scale and each channel's table offset along a run of CHUNK interleaved values:
        # numpy combines arrays of one length far faster than it broadcasts a trailing axis of 3
        self._rows = tuple(np.tile(a, pixels) for a in (self.lo, self.scale, offset))
        self._index = np.empty(pixels * self.channels, np.intp)

    def levels(self, values: np.ndarray) -> np.ndarray:
        """Tone values ``(k, P)`` float32 (``P`` interleaved values of ``channels`` channels a row)
        replaced by their levels, in place, in runs of :data:`CHUNK` values (the temporaries stay
        in cache); returns ``values``."""
        flat = values.reshape(-1)  # a row starts at channel 0, as every run does
        for start in range(0, len(flat), len(self._index)):
            run = flat[start : start + len(self._index)]
            lo, scale, offset = (a[: len(run)] for a in self._rows)
            index = self._index[: len(run)]
            run -= lo
            run *= scale
            np.fmax(run, 0, out=run)  # fmax/fmin as OpenCL's clamp: NaN (no valid map makes one) -> 0
            np.fmin(run, BINS - 1, out=run)
            np.copyto(index, run, casting="unsafe")  # truncation, as astype
            index += offset
            np.take(self._flat, index, out=run, mode="clip")  # intp and in range: no copy, no buffer
        if not np.shares_memory(flat, values):  # values were not contiguous: flat is a copy
            values[...] = flat.reshape(values.shape)
        return values
