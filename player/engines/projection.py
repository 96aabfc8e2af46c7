"""The projection ``frame = mean + sum_i coef_i * basis[i]`` to uint8, shared by the modes
whose frames are a linear combination of stored rows (``lds``, ``mixture``), for up to
``frames`` coefficient vectors per pass over the basis, with a model's fine detail
(:mod:`.detail`) added in the same pass and, where the model has a colour set
(:mod:`dynatex.tiledb.gamut`), every pixel whose colour the source never had moved to the
nearest one it had as it is stored (:func:`snap_colours`), or, where the model has colour sets
per region of the frame, into the sets of the pixel's four nearest regions, blended by its
position between their centres so that no region's edge shows (:func:`snap_local`).

Each frame reads the whole basis, so one frame at a time is bound by memory bandwidth; k
frames per pass read it once (a matrix-matrix product), which is what a caller that knows
its next frames (a file, a look-ahead) gains from.

OpenCL (:class:`ProjectorOpenCL`): kernel ``project`` of ``kernels/projection.cl`` over a blocked
copy of the basis (for each group of ``GROUP`` values, its ``n x GROUP`` sub-matrix is
contiguous), built once and with its arguments set once; per pass one small upload of the
coefficients (and the detail's layers) and one launch into the caller's array (or a device
buffer copied into it). numpy: :class:`ProjectorReference` (one ``coef (k x n) @ basis``
GEMM). :func:`open_projector` picks one.

Tolerance: the two backends, and k frames against one at a time, sum in different orders in
float32, so a value may round to the neighbouring integer (at most 1 apart, on a small share
of values); the detail then sees those integers exactly as a separate pass would, and the
colour set (integers alone) is applied exactly. A model learned on tone values
(:mod:`dynatex.tiledb.tone`) maps each sum to a level through its lookup instead of rounding it;
the lookup's bins are finer than its levels' steps, so a sum that differs in its last bit gives a
level at most 1 apart there too.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from ...tiledb.detail import DetailModel
from ...tiledb.gamut import GamutModel, LocalGamut
from ...tiledb.tone import BINS as TONE_BINS
from ...tiledb.tone import ToneModel
from ..pixels import pixel_format
from .detail import Detail, DetailReference, colour_bins
from .tone import ToneLookup

#: Pixels per work-item of ``project`` (``PIXELS`` in the kernel): a group is ``16 * channels`` values.
PIXELS = 16
#: Values after each frame's coefficients in the kernel's upload: its detail layers (``LAYER_FLOATS``)
LAYER_FLOATS = 8
#: Work-group size: left to choose, PoCL may make few large groups that leave a core idle
#: (CHANGELOG.md has the measurement).
LOCAL = 32
#: (height, width) of the RGB frames at which the device self-test times this engine against
#: numpy (:data:`dynatex.player.opencl.selftest.SPEED_CASES`): a basis beyond any cache, and a
#: 720p one several times larger; a player takes the figure of the size nearest its own
SPEED_SIZES = ((288, 352), (720, 1280))
#: frames per pass of the self-test's look-ahead figures (any look-ahead above 1 takes them)
SPEED_PER_PASS = 8
#: basis rows of the self-test's figures: numpy's cost a frame has a part that grows with the
#: pixels alone (the mean, the rounding to bytes), OpenCL's grows with rows x pixels, so which is
#: faster changes with the rows; a player takes the count nearest its own (log scale). The
#: self-test itself measures :data:`SPEED_ROWS_SELFTEST` (lds's default), the others the first
#: player that needs them.
SPEED_ROWS = (16, 50, 150)
SPEED_ROWS_SELFTEST = 50


def speed_case(
    precision: str, values: int, per_pass: int, detail: bool = False, rows: int = SPEED_ROWS_SELFTEST
) -> str:
    """The self-test's speed figure that decides ``backend="auto"`` for a projection of ``values``
    values a frame through ``rows`` basis rows in ``precision`` with ``per_pass`` frames per pass,
    with the fine detail or without (the numpy reference adds it in passes of its own): the
    measured size and row count nearest in log scale
    (``"projection float32 1280x720, 150 rows, 8 per pass, detail"``; 50 rows go unnamed)."""
    h, w = min(SPEED_SIZES, key=lambda s: abs(math.log(max(values, 1) / (s[0] * s[1] * 3))))
    n = min(SPEED_ROWS, key=lambda r: abs(math.log(max(rows, 1) / r)))
    return (
        f"projection {precision} {w}x{h}"
        + (f", {n} rows" if n != SPEED_ROWS_SELFTEST else "")
        + (f", {SPEED_PER_PASS} per pass" if per_pass > 1 else "")
        + (", detail" if detail else "")
    )


def snap_colours(
    frames: np.ndarray, nearest: np.ndarray, rgb: tuple[int, int, int] = (0, 1, 2), away: np.ndarray | None = None
) -> None:
    """Clamp, in place, each pixel of ``frames`` (..., bytes) uint8 whose colour bin
    (``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)``) is not its own ``nearest`` entry into that
    bin, channel by channel (the closest colour of the bin); ``rgb``: the bytes of r, g, b;
    ``away``: ``nearest != arange(32**3)``, where the caller keeps it.

    >>> nearest = np.arange(32**3, dtype=np.uint16); nearest[(0 * 32 + 25) * 32 + 25] = 25 * 1024
    >>> px = np.array([[[3, 201, 202]]], np.uint8); snap_colours(px, nearest); px.tolist()
    [[[200, 7, 7]]]
    """
    if away is None:
        away = nearest != np.arange(len(nearest), dtype=nearest.dtype)
    bins = colour_bins(frames, rgb)
    out = away.take(bins)
    if not out.any():
        return
    at = np.nonzero(out)
    for i, v in zip(rgb, into_bins([frames[(*at, i)] for i in rgb], nearest.take(bins[at]))):
        frames[(*at, i)] = v


def into_bins(channels: Any, t: np.ndarray) -> list[np.ndarray]:
    """The r, g and b values ``channels`` each clamped into the levels colour bins ``t`` span."""
    return [np.clip(v, lo, lo + 7) for v, lo in zip(channels, ((t >> s & 31) << 3 for s in (10, 5, 0)))]


def bin_of(colour: np.ndarray) -> np.ndarray:
    """The colour bins of ``colour`` (3, len) int32 levels r, g, b."""
    return (colour[0] >> 3 << 10) | (colour[1] >> 3 << 5) | (colour[2] >> 3)


#: Fixed-point bits of a pixel's weight along each axis between two region centres (the local
#: colour sets' blend, :func:`snap_local`): a pixel's four weights are products out of ``2**16``.
WEIGHT_BITS = 8
#: Passes of the local colour sets' blend: a blend of colours from different sets can lie in none
#: of them (CHANGELOG.md has the measurement); a second pass blends such a pixel again.
LOCAL_PASSES = 2
#: Regions whose local colour sets :func:`cell_sets` lays out at a time
SETS_AT_ONCE = 64
#: Bytes of the basis the OpenCL engine lays out on the host at a time on its way to the device
SLAB_BYTES = 1 << 26
#: Pixels numpy's :func:`snap_local` treats at once: its temporaries stay in a core's cache
LOCAL_CHUNK = 1 << 17


def region_axis(n: int, block: int, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along an axis of ``n`` pixels and ``count`` regions of ``block`` pixels: each pixel's lower
    and upper region, the two whose centres it lies between (clamped to ``0..count - 1``), and the
    upper's weight out of ``2**WEIGHT_BITS`` (integers, as the kernel computes them).

    >>> [a.tolist() for a in region_axis(8, 4, 2)]
    [[0, 0, 0, 0, 0, 0, 1, 1], [0, 0, 1, 1, 1, 1, 1, 1], [160, 224, 32, 96, 160, 224, 32, 96]]
    """
    d = 2 * np.arange(n, dtype=np.int64) + 1 - block  # twice the offset from region 0's centre
    lower = d // (2 * block)
    weight = (((d - lower * 2 * block) << WEIGHT_BITS) + block) // (2 * block)
    return np.clip(lower, 0, count - 1), np.clip(lower + 1, 0, count - 1), weight


def cell_sub(r: Any, g: Any, b: Any) -> Any:
    """The index (0..7) of a colour's bin among the 8 bins of its 16-level cell."""
    return ((r >> 1) & 4) | ((g >> 2) & 2) | ((b >> 3) & 1)


def cell_sets(model: LocalGamut) -> np.ndarray:
    """:attr:`LocalColours.sets` of a model's local colour sets, laid out :data:`SETS_AT_ONCE`
    regions at a time (all of them unpacked take 8 bytes a bin)."""
    out = np.empty(model.nearest.size, np.uint32)
    for r in range(0, len(model.inside), SETS_AT_ONCE):
        bits = np.unpackbits(model.inside[r : r + SETS_AT_ONCE], axis=1, bitorder="little")
        bits = bits.reshape(-1, 16, 2, 16, 2, 16, 2).transpose(0, 1, 3, 5, 2, 4, 6)
        held = np.packbits(bits.reshape(-1, 4096, 8), axis=2, bitorder="little")[..., 0].astype(np.uint32)
        out[r * 4096 : r * 4096 + held.size] = model.nearest[r : r + SETS_AT_ONCE].reshape(-1) | held.reshape(-1) << 16
    return out


class LocalColours:
    """A model's local colour sets (:class:`~dynatex.tiledb.gamut.LocalGamut`) laid out for a
    ``height`` x ``width`` frame: each pixel's four nearest regions and their weights along each
    axis (:func:`region_axis`); per quad, the bins all four of its regions hold and those one of
    them holds (:attr:`quads`, both backends); per region and 16-level cell, one entry for the
    blend (:attr:`sets`, both backends); and (numpy, on first use) each pixel's quad and regions.

    A quad is the four regions around a corner where four region centres meet: the pixels between
    those centres blend those four regions' sets, so a pixel whose colour its quad's regions all
    hold is left as it is with one lookup, and one whose blend one of them holds is done."""

    def __init__(self, model: LocalGamut, clip: np.ndarray, height: int, width: int) -> None:
        self.model = model
        #: the clip's map (:class:`~dynatex.tiledb.gamut.GamutModel`'s ``nearest``), applied to a blend
        #: last, and where it moves a bin (numpy's)
        self.clip = np.ascontiguousarray(clip, np.uint16)
        self.away = self.clip != np.arange(len(self.clip), dtype=np.uint16)
        self.block = model.block
        self.rows, self.cols = model.regions(height, width)
        self._y = region_axis(height, self.block, self.rows)
        self._x = region_axis(width, self.block, self.cols)
        # the quads: (rows + 1) x (cols + 1), quad (qy, qx) between region rows qy - 1 and qy
        # and columns qx - 1 and qx, each clamped (the frame's edges: the regions along that axis are one)
        inside = model.inside.reshape(self.rows, self.cols, -1)
        ry, rx = np.arange(self.rows + 1), np.arange(self.cols + 1)
        lo_y, hi_y = np.maximum(ry - 1, 0), np.minimum(ry, self.rows - 1)
        lo_x, hi_x = np.maximum(rx - 1, 0), np.minimum(rx, self.cols - 1)
        #: per quad, the bins all its four regions hold ([:, 0]) and those one of them holds
        #: ([:, 1]), packed as ``model.inside``: uint8 ``((rows + 1) * (cols + 1), 2, 4096)``
        four = inside[lo_y][:, lo_x], inside[lo_y][:, hi_x], inside[hi_y][:, lo_x], inside[hi_y][:, hi_x]
        self.quads = np.stack(
            [four[0] & four[1] & four[2] & four[3], four[0] | four[1] | four[2] | four[3]], axis=2
        ).reshape(-1, 2, inside.shape[-1])
        #: per region and 16-level cell, one lookup for the blend: bits 0..14 the bin the region's
        #: map names for the cell, bit 16 + k whether the region holds the cell's k-th bin
        #: (:func:`cell_sub`): uint32 ``(regions * 4096,)`` (both backends)
        self.sets = cell_sets(model)

    @functools.cached_property
    def quad_base(self) -> np.ndarray:
        """Each pixel's quad times the bins per quad (a key's base into :attr:`quad_lacks`):
        int32 ``(height * width,)`` (numpy's alone, as the rest)."""
        (y0, y1, _), (x0, x1, _) = self._y, self._x
        qy, qx = y0 + (y1 != 0), x0 + (x1 != 0)  # quad q lies between regions q - 1 and q, clamped
        return ((qy[:, None] * (self.cols + 1) + qx[None, :]) << 15).astype(np.int32).reshape(-1)

    @functools.cached_property
    def packed(self) -> np.ndarray:
        """Per pixel, packed in an int64: its upper-left region << 20, lower row apart << 19, right
        column apart << 18, the weight of the lower row << 9 and of the right column."""
        (y0, y1, wy), (x0, x1, wx) = self._y, self._x
        return (
            ((y0[:, None] * self.cols + x0[None, :]) << 20)
            | ((y1 != y0)[:, None] << 19)
            | ((x1 != x0)[None, :] << 18)
            | (wy[:, None] << 9)
            | wx[None, :]
        ).reshape(-1)

    def regions_and_weights(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The four regions (upper-left, upper-right, lower-left, lower-right) of the flat
        ``pixels`` and their weights, out of ``2**(2 * WEIGHT_BITS)`` (each int32 ``(4, len)``)."""
        p = self.packed.take(pixels)
        r = (p >> 20).astype(np.int32)
        down, right = (p >> 19 & 1).astype(np.int32) * self.cols, (p >> 18 & 1).astype(np.int32)
        one = 1 << WEIGHT_BITS
        wy, wx = (p >> 9 & 511).astype(np.int32), (p & 511).astype(np.int32)
        regions = np.stack([r, r + right, r + down, r + down + right])
        return regions, np.stack([(one - wy) * (one - wx), (one - wy) * wx, wy * (one - wx), wy * wx])

    @functools.cached_property
    def quad_lacks(self) -> np.ndarray:
        """The bins one of the four regions of each quad lacks (not all hold: :attr:`quads`), one
        bool per quad and bin, flat (numpy's alone)."""
        return ~np.unpackbits(self.quads[:, 0], axis=1, bitorder="little").astype(bool).reshape(-1)

    @functools.cached_property
    def _quad_any(self) -> np.ndarray:
        """:attr:`quads`' second half (the bins one of the four regions holds), contiguous."""
        return np.ascontiguousarray(self.quads[:, 1]).reshape(-1)

    def quad_any(self, keys: np.ndarray) -> np.ndarray:
        """Whether one of the four regions holds each key (a pixel's :attr:`quad_base` + its bin)."""
        return (self._quad_any.take(keys >> 3, mode="clip") >> (keys & 7) & 1).astype(bool)


def snap_local(frame: np.ndarray, local: LocalColours, rgb: tuple[int, int, int] = (0, 1, 2)) -> None:
    """Move, in place, each pixel of ``frame`` (H, W, bytes) uint8 into the colour sets of its
    four nearest regions, blended by its position between their centres, so that the sets change
    smoothly across the frame (no edge where two regions meet).

    A colour every one of the four holds (its quad's set, :attr:`LocalColours.quads`: one lookup)
    stays as it is. Otherwise, for each of the four regions the pixel's colour is kept where the
    region holds its bin, else clamped, channel by channel, into the bin the region's map names
    for its 16-level cell; the four colours are blended with the pixel's weights
    (:meth:`LocalColours.regions_and_weights`, integers: ``(sum w_k c_k + 2**15) >> 16``). Near
    a region's centre its set weighs most, and past the outermost centres (the frame's edges)
    the regions along that axis are one. Up to :data:`LOCAL_PASSES` passes, each over the pixels
    the one before left in none of the four sets (:meth:`LocalColours.quad_any`). Last, a blended
    colour outside the clip's set is clamped into its nearest bin there (:attr:`LocalColours.clip`):
    a blend of colours from different regions' sets can lie outside every one of them and outside
    the clip's, which holds them all.

    >>> from dynatex.tiledb.gamut import LocalGamut
    >>> held = np.zeros(32768, bool); held[(25 * 32 + 0) * 32 + 0] = True  # red alone
    >>> near = np.full((1, 4096), 25 * 1024, np.uint16)
    >>> clip = np.arange(32768, dtype=np.uint16)  # the clip's set: every colour
    >>> loc = LocalColours(LocalGamut(1, np.packbits(held, bitorder="little")[None], near), clip, 1, 1)
    >>> px = np.array([[[3, 201, 202]]], np.uint8); snap_local(px, loc); px.tolist()
    [[[200, 7, 7]]]
    """
    flat = frame.reshape(-1, frame.shape[-1])  # a view: the caller's frames are C-contiguous
    for start in range(0, len(flat), LOCAL_CHUNK):
        snap_local_run(flat[start : start + LOCAL_CHUNK], start, local, rgb)


def snap_local_run(flat: np.ndarray, start: int, local: LocalColours, rgb: tuple[int, int, int]) -> None:
    """:func:`snap_local` on the pixels ``flat`` (len, bytes), the first the frame's pixel ``start``."""
    bins = colour_bins(flat, rgb)
    pixels = np.flatnonzero(local.quad_lacks[local.quad_base[start : start + len(flat)] + bins])
    if not len(pixels):
        return
    colour = np.take(flat, pixels, axis=0).T[list(rgb)].astype(np.int32)  # (3, len): r, g, b
    bins = bins[pixels].astype(np.int32)
    regions, weights = local.regions_and_weights(pixels + start)
    for step in range(LOCAL_PASSES):
        if step:  # the pixels the blend left in none of the four sets
            bins = bin_of(colour)
            todo = np.flatnonzero(~local.quad_any(local.quad_base[pixels + start] + bins))
            if not len(todo):
                break
            colour[:, todo] = blend_sets(colour[:, todo], bins[todo], regions[:, todo], weights[:, todo], local)
        else:
            colour = blend_sets(colour, bins, regions, weights, local)
    bins = bin_of(colour)
    outside = np.flatnonzero(local.away.take(bins))
    if len(outside):
        colour[:, outside] = into_bins(colour[:, outside], local.clip.take(bins[outside]).astype(np.int32))
    for i, v in zip(rgb, colour):
        flat[pixels, i] = v


def blend_sets(colour: np.ndarray, bins: np.ndarray, regions: np.ndarray, weights: np.ndarray, local: LocalColours):
    """One pass of :func:`snap_local`'s blend: ``colour`` (3, len) int32 levels, ``bins`` their
    colour bins, ``regions`` and ``weights`` (4, len) (:meth:`LocalColours.regions_and_weights`);
    the blended colours (3, len) int32. Each region clamps a colour, channel by channel, into the
    bin its map names for the colour's 16-level cell, or into the colour's own bin (no change)
    where the region holds it."""
    cells = (colour[0] >> 4 << 8) | (colour[1] >> 4 << 4) | (colour[2] >> 4)
    regions = regions << 12
    regions += cells
    target = local.sets.take(regions, mode="clip").view(np.int32)
    held = (target >> (cell_sub(*colour) + 16)) & 1
    target &= 0x7FFF
    np.copyto(target, bins, where=held.astype(bool))
    out = np.empty_like(colour)
    lo, value = regions, held  # their memory reused
    for i, shift in enumerate((10, 5, 0)):
        # the target's levels in the channel: lo .. lo + 7
        np.right_shift(target, shift, out=lo)
        lo &= 31
        lo <<= 3
        np.maximum(lo, colour[i], out=value)
        lo += 7
        np.minimum(value, lo, out=value)
        value *= weights
        np.add.reduce(value, axis=0, dtype=np.int32, out=out[i])
    out += 1 << (2 * WEIGHT_BITS - 1)
    out >>= 2 * WEIGHT_BITS
    return out


def blocked_basis(basis: np.ndarray | tuple[np.ndarray, ...], block: int) -> np.ndarray:
    """``(n, P)`` (or row blocks of ``P`` columns stacked) -> ``(ceil(P / block), n, block)``,
    zero-padded: the kernel's streaming layout."""
    parts = row_blocks(basis)
    n, p = basis_shape(parts)
    blocks, full = -(-p // block), p // block
    out = np.zeros((blocks, n, block), parts[0].dtype)
    i = 0
    for part in parts:
        rows = slice(i, i + len(part))
        out[:full, rows] = part[:, : full * block].reshape(len(part), full, block).transpose(1, 0, 2)
        if blocks != full:
            out[full, rows, : p - full * block] = part[:, full * block :]
        i += len(part)
    return out


def row_blocks(basis: np.ndarray | tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """A basis given as one ``(n, P)`` array or as row blocks stacked (a tuple): the blocks."""
    return tuple(basis) if isinstance(basis, (tuple, list)) else (basis,)


def basis_shape(basis: np.ndarray | tuple[np.ndarray, ...]) -> tuple[int, int]:
    """``(n, P)`` of a basis given as one array or as row blocks stacked."""
    parts = row_blocks(basis)
    return sum(len(b) for b in parts), parts[0].shape[1]


class Projector:
    """Projects coefficient vectors through a fixed basis into ``(H, W, bytes)`` uint8 frames.

    The interface of both projection engines (:func:`open_projector` picks one). The
    coefficients of frame ``j`` of a pass are written into ``coefs[j]`` (float32; :attr:`coef`
    is ``coefs[0]``) and :meth:`run` projects them.

    Parameters
    ----------
    basis : (n, P) float32 or float16, or a tuple of such row blocks
        Rows to combine (a tuple: its blocks' rows in turn, so that a caller need not copy them
        into one array); ``P = H * W * channels``. float16 halves the bytes read per frame.
    mean : (P,) float32
        Added to every frame.
    shape : (H, W, bytes)
        Output frame shape (``bytes`` those of a pixel of ``format``).
    channels : {1, 3}
        Values per pixel in ``basis``; grey frames are replicated to RGB.
    format : {"RGB", "RGBA", "BGRA"}
        Output pixel format (:data:`~dynatex.player.pixels.FORMATS`).
    frames : int
        Most frames one pass projects.
    detail : DetailModel, optional
        The model's fine detail, added to a pass given its layers (:attr:`detail` describes it).
    gamut : GamutModel, optional
        The source's colour set (``channels`` 3 only): every frame's pixels outside it are moved
        to the nearest colour in it (:func:`snap_colours`), after the detail.
    tone : ToneModel, optional
        The model was learned on tone values: the projected values are mapped to levels by its
        lookup (:class:`~.tone.ToneLookup`) instead of rounded and saturated.
    """

    backend = ""

    def __init__(
        self,
        basis: np.ndarray,
        mean: np.ndarray,
        *,
        shape: tuple[int, int, int],
        channels: int,
        format: str = "RGB",
        frames: int = 1,
        detail: DetailModel | None = None,
        gamut: GamutModel | None = None,
        tone: ToneModel | None = None,
    ) -> None:
        self.format = pixel_format(format)
        parts = row_blocks(basis)
        self.n, self.values = basis_shape(parts)
        self.shape = tuple(shape)
        self.channels = channels
        self.half = parts[0].dtype == np.float16
        self.basis_bytes = sum(b.nbytes for b in parts)
        self.frames = int(frames)
        self.coefs = np.zeros((self.frames, max(self.n, 1)), np.float32)
        self.coef = self.coefs[0]
        #: the detail's arrays and layer schedule (None: the model has none)
        self.detail: Detail | None = None
        if detail is not None:
            self.detail = DetailReference(detail, shape=self.shape, channels=channels, format=format)
        #: the map from tone values to levels (None: the model was learned on levels)
        self.tone = None if tone is None else ToneLookup(tone)
        #: each colour bin's nearest bin of the source's colour set (None: the model has none)
        self.nearest: np.ndarray | None = None
        #: the source's colour set per region of the frame, applied instead of :attr:`nearest` (None: none)
        self.local: LocalColours | None = None
        if gamut is not None and channels == 3:
            self.nearest = np.ascontiguousarray(gamut.nearest, np.uint16)
            self._away = self.nearest != np.arange(len(self.nearest), dtype=np.uint16)
            if gamut.local is not None:
                self.local = LocalColours(gamut.local, gamut.nearest, *self.shape[:2])

    @property
    def bytes_per_frame(self) -> int:
        """The basis and mean read, plus the uint8 frame written, for one frame at a time."""
        return int(self.basis_bytes + 4 * self.values + int(np.prod(self.shape)))

    def run(self, out: np.ndarray, *, count: int | None = None, layers: list | None = None, wait: bool = True):
        """Project :attr:`coef` into ``out`` ((H, W, bytes) uint8, C-contiguous), or with
        ``count`` the first ``count`` rows of :attr:`coefs` into ``out`` ((count, H, W, bytes)).

        ``layers``: each frame's detail layers (:meth:`.Detail.layers`), to add the detail;
        None projects alone. Returns None once ``out`` holds the frames, or (``wait=False``,
        OpenCL) the event after which it does. The coefficients may be changed as soon as
        this returns.
        """
        raise NotImplementedError

    def draw(self, out: np.ndarray, *, count: int | None = None, layers: list | None = None, wait: bool = True):
        """:meth:`run`, in the words of every engine (:class:`~dynatex.player.engines.Engine`)."""
        return self.run(out, count=count, layers=layers, wait=wait)

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for the reference)."""


class ProjectorReference(Projector):
    """The numpy reference: ``coef @ basis + mean`` (k frames: one ``coefs (k x n) @ basis``
    GEMM), rounded and saturated, in float32; the detail by :class:`~.detail.DetailReference`."""

    backend = "numpy"

    def __init__(self, basis: np.ndarray, mean: np.ndarray, **kwargs: Any) -> None:
        super().__init__(basis, mean, **kwargs)
        parts = row_blocks(basis)
        basis = parts[0] if len(parts) == 1 else np.concatenate(parts)  # one GEMM reads one array
        self._basis = basis.astype(np.float32) if self.half else basis
        self._mean = mean

    def run(self, out: np.ndarray, *, count: int | None = None, layers: list | None = None, wait: bool = True):
        h, w = self.shape[:2]
        if count is None:
            frames = (self.coef[: self.n] @ self._basis)[None]
            outs = out[None]
        else:
            frames = self.coefs[:count, : self.n] @ self._basis
            outs = out
        frames += self._mean
        if self.tone is not None:
            frames = self.tone.levels(frames)
        else:
            np.rint(frames, out=frames)
            np.clip(frames, 0, 255, out=frames)
        for j, frame in enumerate(frames):
            o = outs[j]
            frame = frame.reshape(h, w, self.channels)
            if layers is not None:  # the detail reads the projected integers from the float frame
                self.detail.apply(o, layers[j], projected=frame)
            elif self.format.name == "RGB":
                o[...] = frame
            else:
                self.format.from_rgb(np.broadcast_to(frame, (h, w, 3)), o)
            if self.local is not None:
                snap_local(o, self.local, self.format.rgb)
            elif self.nearest is not None:
                snap_colours(o, self.nearest, self.format.rgb, self._away)


class ProjectorOpenCL(Projector):
    """Kernel ``project`` of ``kernels/projection.cl`` over a blocked copy of the basis (module docstring).

    ``ctx`` and ``queue`` belong to the caller (the mode's player); the engine owns its buffers.
    The kernel with the detail and the one without are built once each, when first needed.
    """

    backend = "opencl"

    def __init__(self, basis: np.ndarray, mean: np.ndarray, *, ctx: Any, queue: Any, **kwargs: Any) -> None:
        super().__init__(basis, mean, **kwargs)
        import pyopencl as cl

        self.ctx, self.queue = ctx, queue
        # a pass's one upload, a row per frame: the coefficients, then the detail's layers
        width = self.coefs.shape[1]
        self._upload = np.zeros((self.frames, width + LAYER_FLOATS), np.float32)
        self.coefs = self._upload[:, :width]
        self.coef = self.coefs[0]
        group = PIXELS * self.channels
        groups = -(-self.values // group)
        mean_p = np.zeros(groups * group, np.float32)
        mean_p[: self.values] = mean
        mf = cl.mem_flags
        self._bufs: dict[str, Any] = {
            "basis": self._blocked_buffer(basis, groups, group),
            "mean": cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=mean_p),
            "coef": cl.Buffer(ctx, mf.READ_ONLY, self._upload.nbytes),
        }
        d = self.detail
        if d is None:
            dummy = np.zeros(1, np.uint8)
            arrays = {name: dummy for name in ("vol", "low", "high", "colours")}
            arrays["gain"] = np.zeros(1, np.float32)
        else:
            # each volume row's first PIXELS - 1 pixels repeated after its end (the kernel's header)
            vol = np.ascontiguousarray(d.volume[:, :, np.arange(d.vw + PIXELS - 1) % d.vw])
            arrays = {"vol": vol, "gain": d.gain.reshape(-1), "low": d.low, "high": d.high, "colours": d.colours}
        arrays["nearest"] = np.zeros(1, np.uint16) if self.nearest is None else self.nearest
        loc = self.local
        arrays["local_sets"] = np.zeros(1, np.uint32) if loc is None else loc.sets
        arrays["local_quads"] = np.zeros(1, np.uint8) if loc is None else loc.quads
        t = self.tone
        arrays["tone"] = np.zeros(1, np.float32) if t is None else np.concatenate([t.lo, t.scale])
        arrays["tone_table"] = np.zeros(1, np.uint8) if t is None else t.table
        for name, a in arrays.items():
            self._bufs[name] = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
        self._kernels: dict[bool, tuple[Any, Any]] = {}
        self._frame_bytes = int(np.prod(self.shape))
        self._gsize = (-(-groups // LOCAL) * LOCAL,)
        self._lsize = (LOCAL,)
        self.out = None
        self._kernel(self.detail is not None)

    def _blocked_buffer(self, basis: np.ndarray | tuple[np.ndarray, ...], groups: int, group: int) -> Any:
        """The device's copy of the basis in the kernel's layout (:func:`blocked_basis`), written
        in slabs of whole groups, so that the host holds no blocked copy of it beside the caller's rows."""
        import pyopencl as cl

        parts = row_blocks(basis)
        itemsize = parts[0].dtype.itemsize
        per_group = self.n * group * itemsize
        buf = cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY, groups * per_group)
        slab = max(1, SLAB_BYTES // per_group)
        for g0 in range(0, groups, slab):
            cols = slice(g0 * group, min(g0 + slab, groups) * group)
            blocked = blocked_basis(tuple(b[:, cols] for b in parts), group)
            cl.enqueue_copy(self.queue, buf, blocked, dst_offset=g0 * per_group, is_blocking=True)
        return buf

    def _kernel(self, detail: bool):
        """The kernel with or without the detail, built and bound on first use; binds :attr:`out` to it."""
        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel

        if detail not in self._kernels:
            vh, vw = (self.detail.vh, self.detail.vw) if detail else (1, 1)
            defines = {"HALF": self.half, "CHANNELS": self.channels, "DETAIL": detail, "VH": vh, "VW": vw}
            defines["GAMUT"] = self.nearest is not None
            defines["TONE"], defines["TONE_BINS"] = self.tone is not None, TONE_BINS
            loc = self.local
            defines["LOCAL"] = loc is not None
            defines["LOCAL_BLOCK"], defines["LOCAL_ROWS"], defines["LOCAL_COLS"] = (
                (loc.block, loc.rows, loc.cols) if loc else (1, 1, 1)
            )
            defines["LOCAL_WEIGHT_BITS"], defines["LOCAL_PASSES"] = WEIGHT_BITS, LOCAL_PASSES
            prog = build_program(self.ctx, ("pixels.cl", "projection.cl"), {**defines, **self.format.defines})
            k = Kernel(prog, "project")
            k.set(
                n=np.int32(self.n),
                values=np.int32(self.values),
                stride=np.int32(self._upload.shape[1]),
                width=np.int32(self.shape[1]),
                **self._bufs,
            )
            self._kernels[detail] = k, FrameOut(self.ctx, self.queue, k, "out", self.frames * self._frame_bytes)
        k, self.out = self._kernels[detail]
        return k

    @property
    def direct(self) -> bool:
        """Frames are written straight into the caller's array (no copy)."""
        return self.out.direct

    def _prepare(self, count: int | None, layers: list | None, wait: bool):
        """Bind the kernel for ``layers`` and upload what the pass reads; the kernel."""
        import pyopencl as cl

        k = self._kernel(layers is not None)
        frames = 1 if count is None else count
        k.set(frames=np.int32(frames))
        if layers is not None:  # the layers' integers (volume sizes) are exact in float32
            for j, ((t0, oy0, ox0, w0), (t1, oy1, ox1, w1)) in enumerate(layers[:frames]):
                self._upload[j, -LAYER_FLOATS:] = (t0, oy0, ox0, t1, oy1, ox1, w0, w1)
        # once this copy is done the caller may change the coefficients (a frame it waits for
        # is done with them anyway)
        cl.enqueue_copy(self.queue, self._bufs["coef"], self._upload[:frames], is_blocking=not wait)
        return k

    def run(self, out: np.ndarray, *, count: int | None = None, layers: list | None = None, wait: bool = True):
        self._prepare(count, layers, wait)
        return self.out.launch(out, self._gsize, self._lsize, wait=wait)

    def run_on_device(self, *, count: int | None = None, layers: list | None = None):
        """Project into the device frame buffer ``out.buffer`` alone (the benchmarks' kernel time); the event."""
        self._prepare(count, layers, False)
        return self.out.launch_on_device(self._gsize, self._lsize)

    def close(self) -> None:
        self.queue.finish()
        for buf in self.__dict__.pop("_bufs", {}).values():
            buf.release()
        for _, frames in self.__dict__.pop("_kernels", {}).values():
            frames.buffer.release()


def open_projector(
    basis: np.ndarray,
    mean: np.ndarray,
    *,
    shape: tuple[int, int, int],
    channels: int,
    ctx: Any = None,
    queue: Any = None,
    format: str = "RGB",
    frames: int = 1,
    detail: DetailModel | None = None,
    gamut: GamutModel | None = None,
    tone: ToneModel | None = None,
) -> Projector:
    """The OpenCL projection engine on ``ctx``/``queue``, or the numpy reference when ``ctx`` is None."""
    kwargs = dict(shape=shape, channels=channels, format=format, frames=frames, detail=detail, gamut=gamut, tone=tone)
    if ctx is None:
        return ProjectorReference(basis, mean, **kwargs)
    return ProjectorOpenCL(basis, mean, ctx=ctx, queue=queue, **kwargs)
