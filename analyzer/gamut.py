"""Learning the source's colour set as a nearest-colour map (the ``gamut`` part of ``lds`` and
``mixture``, :mod:`dynatex.tiledb.gamut`).

The set: the colour bins (8 levels per channel, those of
:func:`~dynatex.analyzer.metrics.out_of_gamut_share`) that at least :data:`MIN_PIXELS` pixels
of the clip hold; a bin fewer pixels hold is a colour of a lone pixel or two (coding noise),
which the rest of the clip need not show. Each bin maps to its nearest bin of the set in
Euclidean distance (an exact distance transform over the ``32**3`` cube), so the player moves
a colour the clip never had to the closest one it had: a cyan overshoot on a red-on-sky edge
becomes the sky's blue, a red lamp's overshoot past off its grey glass.

The set is the occupied bins, not the metric's set grown by a bin: a colour moved to the edge
of the grown set of the whole clip is still outside the grown set of the half of the clip that
lacks the bin next to it, which the metric counts (on the flag clip that keeps 5e-4 of the
output's pixels outside, against the source's own 3e-7).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..framestats import CHUNK
from ..tiledb.gamut import BIN_BITS, GamutModel
from .metrics.gamut import colour_bins

#: Pixels of the clip a colour bin must hold to be in the set.
MIN_PIXELS = 4


def learn_gamut(frames: np.ndarray, *, min_pixels: int = MIN_PIXELS) -> GamutModel | None:
    """The nearest-colour map of ``frames`` ``(T, H, W, 3)`` uint8 (None for grey frames).

    Examples
    --------
    >>> red = np.zeros((4, 2, 2, 3), np.uint8); red[..., 0] = 200
    >>> g = learn_gamut(red)
    >>> cyan = (0 >> 3) * 1024 + (200 >> 3) * 32 + (200 >> 3)
    >>> int(g.nearest[cyan]) >> 10, (int(g.nearest[cyan]) >> 5) & 31, int(g.nearest[cyan]) & 31
    (25, 0, 0)
    """
    if frames.ndim != 4 or frames.shape[-1] != 3:
        return None
    n = 1 << BIN_BITS
    counts = np.zeros(n**3, np.int64)
    for lo in range(0, len(frames), CHUNK):
        counts += np.bincount(colour_bins(frames[lo : lo + CHUNK]), minlength=n**3)
    inside = counts >= min(min_pixels, int(counts.max()))
    idx = ndimage.distance_transform_edt(~inside.reshape(n, n, n), return_distances=False, return_indices=True)
    nearest = ((idx[0] * n + idx[1]) * n + idx[2]).astype(np.uint16).reshape(-1)
    return GamutModel(nearest=nearest, info={"min_pixels": int(min_pixels), "colours": int(inside.sum())})
