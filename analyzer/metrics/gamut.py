"""Colours the source never had: the output's share outside the source's colour set,
calibrated by the source's own share between its halves.
"""

from __future__ import annotations

import numpy as np

from ...checks import check_frames
from ...errors import InvalidArgumentError
from ...framestats import CHUNK
from ...tiledb.gamut import BIN_BITS
from .memo import remembered

# -- colours the source never had -----------------------------------------------------------
#: bits per channel of the colour bins (bins 8 levels wide): the stored gamut part's
GAMUT_BITS = BIN_BITS


def colour_bins(frames: np.ndarray) -> np.ndarray:
    """Each pixel's colour bin, ``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)`` (grey: r = g = b)."""
    f = np.asarray(frames)
    if f.dtype != np.uint8:
        f = np.clip(np.rint(f), 0, 255).astype(np.uint8)
    if f.ndim == 3:
        f = f[..., None]
    f = f.reshape(-1, f.shape[-1]) >> (8 - GAMUT_BITS)
    if f.shape[1] == 1:
        f = np.repeat(f, 3, axis=1)
    n = 1 << GAMUT_BITS
    return (f[:, 0].astype(np.int32) * n + f[:, 1]) * n + f[:, 2]


@remembered
def colour_set(frames: np.ndarray) -> np.ndarray:
    """The colour bins ``frames`` occupy, grown by one bin in every direction (26 neighbours):
    a bool per bin of :func:`colour_bins` (``32**3``), the set :func:`out_of_gamut_share` tests against."""
    n = 1 << GAMUT_BITS
    occ = np.zeros(n**3, bool)
    for lo in range(0, len(frames), CHUNK):
        occ[colour_bins(frames[lo : lo + CHUNK])] = True
    occ = np.pad(occ.reshape(n, n, n), 1)
    grown = np.zeros((n, n, n), bool)
    for dr in range(3):
        for dg in range(3):
            for db in range(3):
                grown |= occ[dr : dr + n, dg : dg + n, db : db + n]
    return grown.reshape(-1)


def _share_outside(frames: np.ndarray, colours: np.ndarray) -> float:
    outside = total = 0
    for lo in range(0, len(frames), CHUNK):
        bins = colour_bins(frames[lo : lo + CHUNK])
        outside += int(np.count_nonzero(~colours[bins]))
        total += bins.size
    return outside / max(total, 1)


def out_of_gamut_share(output: np.ndarray, source: np.ndarray) -> float:
    """Share of the output's pixels whose colour the source never had.

    A colour is the source's when its 8-level RGB bin, or a neighbouring bin, holds a pixel
    of the source. Measured against each half of the source in turn (first and second half
    of its frames) and averaged, so that it compares directly with :func:`source_gamut_share`,
    the source's own level: an output at or below it has no colours the clip never had.

    Examples
    --------
    >>> red = np.zeros((10, 4, 4, 3), np.uint8); red[..., 0] = 200
    >>> cyan = red.copy(); cyan[..., 0] = 0; cyan[..., 1:] = 200
    >>> out_of_gamut_share(red, red), out_of_gamut_share(np.concatenate([red, cyan]), red)
    (0.0, 0.5)
    """
    output = check_frames(output, name="output", min_frames=1)
    source = check_frames(source, name="source", min_frames=2)
    half = len(source) // 2
    return 0.5 * sum(_share_outside(output, colour_set(part)) for part in (source[:half], source[half:]))


@remembered
def source_gamut_share(source: np.ndarray) -> float:
    """The source's own out-of-gamut level: each half of its frames measured against the other
    (:func:`out_of_gamut_share`), averaged. Colours that appear in one half only count."""
    source = check_frames(source, name="source", min_frames=2)
    half = len(source) // 2
    a, b = source[:half], source[half:]
    return 0.5 * (_share_outside(b, colour_set(a)) + _share_outside(a, colour_set(b)))


# -- colours a region of the frame never had ---------------------------------------------------
#: side in pixels of the square regions :func:`local_out_of_gamut_share` gives a colour set each
LOCAL_BLOCK = 16


def _region_ids(shape: tuple[int, int], block: int) -> tuple[np.ndarray, int]:
    """Each pixel's region (row-major over ``block`` x ``block`` squares) and the region count."""
    h, w = shape
    cols = -(-w // block)
    ids = (np.arange(h)[:, None] // block) * cols + np.arange(w)[None, :] // block
    return ids.reshape(-1).astype(np.int64), (-(-h // block)) * cols


def local_colour_sets(frames: np.ndarray, block: int = LOCAL_BLOCK) -> np.ndarray:
    """Per region of ``block`` x ``block`` pixels, the colour bins its pixels occupy in ``frames``,
    grown by one bin in every direction (as :func:`colour_set`): bool ``(regions, 32**3)``."""
    n = 1 << GAMUT_BITS
    ids, regions = _region_ids(frames.shape[1:3], block)
    occ = np.zeros(regions * n**3, bool)
    for lo in range(0, len(frames), CHUNK):
        part = frames[lo : lo + CHUNK]
        occ[np.tile(ids, len(part)) * n**3 + colour_bins(part)] = True
    occ = np.pad(occ.reshape(regions, n, n, n), ((0, 0), (1, 1), (1, 1), (1, 1)))
    grown = np.zeros((regions, n, n, n), bool)
    for dr in range(3):
        for dg in range(3):
            for db in range(3):
                grown |= occ[:, dr : dr + n, dg : dg + n, db : db + n]
    return grown.reshape(regions, -1)


def _local_share_outside(frames: np.ndarray, sets: np.ndarray, block: int) -> float:
    n = 1 << GAMUT_BITS
    ids, _ = _region_ids(frames.shape[1:3], block)
    flat = sets.reshape(-1)
    outside = total = 0
    for lo in range(0, len(frames), CHUNK):
        part = frames[lo : lo + CHUNK]
        keys = np.tile(ids, len(part)) * n**3 + colour_bins(part)
        outside += int(np.count_nonzero(~flat[keys]))
        total += keys.size
    return outside / max(total, 1)


def local_out_of_gamut_share(output: np.ndarray, source: np.ndarray, *, block: int = LOCAL_BLOCK) -> float:
    """Share of the output's pixels whose colour the source never had in that place: the
    colour set (:func:`colour_set`) of each ``block`` x ``block`` region of the frame, against
    each half of the source in turn, averaged (as :func:`out_of_gamut_share`); the source's own
    level is :func:`source_local_gamut_share`. A clip colour shown where the clip never showed
    it (a flag's green over the stone it flies in front of) counts here, not there.

    Examples
    --------
    >>> red = np.zeros((10, 32, 32, 3), np.uint8); red[..., 0] = 200
    >>> src = red.copy(); src[:, 16:, 16:] = (0, 200, 200)  # cyan in the bottom-right quarter
    >>> moved = red.copy(); moved[:, :16, :16] = (0, 200, 200)  # in the top-left: red where cyan was too
    >>> out_of_gamut_share(moved, src), local_out_of_gamut_share(moved, src)
    (0.0, 0.5)
    """
    output = check_frames(output, name="output", min_frames=1)
    source = check_frames(source, name="source", min_frames=2)
    if output.shape[1:3] != source.shape[1:3]:
        raise InvalidArgumentError(
            f"output frames {output.shape[1:3]} and source frames {source.shape[1:3]} differ in size"
        )
    half = len(source) // 2
    return 0.5 * sum(
        _local_share_outside(output, local_colour_sets(part, block), block) for part in (source[:half], source[half:])
    )


def source_local_gamut_share(source: np.ndarray, *, block: int = LOCAL_BLOCK) -> float:
    """The source's own :func:`local_out_of_gamut_share`: each half against the other, averaged."""
    source = check_frames(source, name="source", min_frames=2)
    half = len(source) // 2
    a, b = source[:half], source[half:]
    return 0.5 * (
        _local_share_outside(b, local_colour_sets(a, block), block)
        + _local_share_outside(a, local_colour_sets(b, block), block)
    )
