"""Learning the source's colour set as a nearest-colour map (the ``gamut`` part of ``lds`` and
``mixture``, :mod:`dynatex.tiledb.gamut`).

The set: the colour bins (8 levels per channel, those of
:func:`~dynatex.analyzer.metrics.out_of_gamut_share`) that at least :data:`MIN_PIXELS` pixels
of the clip hold, and :data:`MIN_SHARE` of them in a large clip; a bin fewer pixels hold is a
colour of a lone pixel or two (coding noise), which the rest of the clip need not show. The
share matters where the set's edge is: a colour the player moves into the set lands in its
nearest bin, which lies at the edge, where bins are rarest; on a 720p clip of 116 frames the
bins held by 4 or 5 of its 1e8 pixels appear in one half of the clip alone, and output moved
into them counted as colours that half never had. Each bin maps to its nearest bin of the set in
Euclidean distance (an exact distance transform over the ``32**3`` cube), so the player moves
a colour the clip never had to the closest one it had: a cyan overshoot on a red-on-sky edge
becomes the sky's blue, a red lamp's overshoot past off its grey glass.

The set is the occupied bins, not the metric's set grown by a bin: a colour moved to the edge
of the grown set of the whole clip is still outside the grown set of the half of the clip that
lacks the bin next to it, which the metric counts (on the flag clip that keeps 5e-4 of the
output's pixels outside, against the source's own 3e-7).

The local sets (:class:`~dynatex.tiledb.gamut.LocalGamut`): the same rule per square region of
:data:`LOCAL_BLOCK` pixels (doubled until there are at most :data:`MAX_REGIONS`), intersected
with the clip's set; each 16-level cell maps to the region's bin nearest to the cell's centre
(its eight bins lie within a bin's diagonal of it, so a finer map, 64 KiB per region, would
move a colour less than a bin less far).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..framestats import CHUNK
from ..tiledb.gamut import BIN_BITS, MAX_REGIONS, GamutModel, LocalGamut
from .metrics.gamut import colour_bins

#: Pixels of the clip a colour bin must hold to be in the set, and the share of the clip's pixels
#: it must hold where that is more (a large clip).
MIN_PIXELS = 4
MIN_SHARE = 1e-7
#: Side in pixels of a region of the local colour sets (doubled until the frame has at most
#: :data:`~dynatex.tiledb.gamut.MAX_REGIONS`).
LOCAL_BLOCK = 16


def learn_gamut(frames: np.ndarray, *, min_pixels: int | None = None) -> GamutModel | None:
    """The nearest-colour map of ``frames`` ``(T, H, W, 3)`` uint8 (None for grey frames); a bin
    is in the set where ``min_pixels`` of the clip's pixels hold it (default :data:`MIN_PIXELS`,
    or :data:`MIN_SHARE` of the pixels where that is more), each region's where as many of its own do.

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
    if min_pixels is None:
        min_pixels = max(MIN_PIXELS, math.ceil(MIN_SHARE * int(counts.sum())))
    inside = counts >= min(min_pixels, int(counts.max()))
    nearest = _nearest(inside).reshape(-1)
    info = {"min_pixels": int(min_pixels), "colours": int(inside.sum())}
    return GamutModel(nearest=nearest, info=info, local=learn_local(frames, inside, min_pixels=min_pixels))


def _nearest(inside: np.ndarray) -> np.ndarray:
    """Each bin's nearest bin (Euclidean) where ``inside`` ``(32768,)`` holds: uint16 ``(32, 32, 32)``."""
    n = 1 << BIN_BITS
    idx = ndimage.distance_transform_edt(~inside.reshape(n, n, n), return_distances=False, return_indices=True)
    return ((idx[0] * n + idx[1]) * n + idx[2]).astype(np.uint16)


#: The centre of each 16-level cell, in bins (a cell spans two bins per channel).
CENTRES = np.stack(np.meshgrid(*[np.arange(16) * 2 + 0.5] * 3, indexing="ij"), axis=-1).reshape(-1, 3)


def learn_local(frames: np.ndarray, clip_set: np.ndarray, *, min_pixels: int = MIN_PIXELS) -> LocalGamut:
    """The colour set of each region of ``frames`` ``(T, H, W, 3)`` uint8 within ``clip_set``
    (bool per bin), as :class:`~dynatex.tiledb.gamut.LocalGamut` (module docstring)."""
    t, h, w = frames.shape[:3]
    block = LOCAL_BLOCK
    while -(-h // block) * -(-w // block) > MAX_REGIONS:
        block *= 2
    cols = -(-w // block)
    bins = 1 << (3 * BIN_BITS)
    region = np.arange(w) // block
    inside, nearest = [], []
    for y0 in range(0, h, block):  # one row of regions at a time: counts of a row's regions alone
        counts = np.zeros(cols * bins, np.int64)
        strip = frames[:, y0 : y0 + block]
        ids = np.broadcast_to(region, strip.shape[1:3]).reshape(-1)
        for lo in range(0, t, CHUNK):
            part = strip[lo : lo + CHUNK]
            counts += np.bincount(np.tile(ids, len(part)) * bins + colour_bins(part), minlength=cols * bins)
        for c in counts.reshape(cols, bins):
            held = (c >= min(min_pixels, int(c.max()))) & clip_set
            if not held.any():
                held = clip_set
            inside.append(np.packbits(held, bitorder="little"))
            members = np.flatnonzero(held)
            _, k = cKDTree(np.stack([members >> 10, (members >> 5) & 31, members & 31], axis=1)).query(CENTRES)
            nearest.append(members[k].astype(np.uint16))
    return LocalGamut(block=block, inside=np.stack(inside), nearest=np.stack(nearest))
