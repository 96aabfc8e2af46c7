"""A quilt of spatio-temporal cuboids (the ``quilt`` group), for time-varying textures.

The analyzer quilts small source blocks carried through the whole sequence onto an output
canvas; what it stores is the result, not the search: for every output pixel the source
pixel it copies (the same for every frame), the placed block it belongs to (the player
jitters time per block) and an optional per-pixel gain (low-pass normalisation). The
player plays it from the stored source frames: ``out[t](y, x) = gain(y, x) *
frames[f(t, y, x)][source_map(y, x)]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from ..checks import MAX_SIDE
from ..errors import InvalidArgumentError
from ._check import Checker
from ._describe import Described
from .source import SourceInfo

#: Gains outside (0, MAX_GAIN] are refused: they would saturate every pixel.
MAX_GAIN = 64.0


@dataclass
class QuiltModel(Described):
    """The quilt of one texture.

    Attributes
    ----------
    source_map : (H_out, W_out, 2) int32
        ``(y, x)`` of the source pixel each output pixel copies, in ``[0, H) x [0, W)``.
    labels : (H_out, W_out) int32
        Index of the placed block each output pixel came from (after the boundary cuts),
        in ``[0, n_blocks)``.
    block_sources : (n_blocks, 2) int32
        ``(y, x)`` top-left corner in the source of each placed block.
    block_positions : (n_blocks, 2) int32
        ``(y, x)`` top-left corner on the output canvas of each placed block (may be
        partly outside the canvas on the bottom and right edges).
    singular_values : (r,) float64
        Singular values of the pixel-by-time matrix, descending.
    rank_error : (r,) float64
        Relative RMS reconstruction error ``||X - X_k|| / ||X||`` of the rank-``k``
        approximation, for ``k = 1 .. r`` (non-increasing, in [0, 1]).
    gain : (H_out, W_out, C) float32 or None
        Per-pixel multiplier applied after the gather (low-pass gain normalisation).
    blend_map, blend_labels, blend_weight : arrays or None
        ``(H_out, W_out, 2)`` int32, ``(H_out, W_out)`` int32 and ``(H_out, W_out)`` float32.
        Cross-fade across the cuts: a second source pixel and its block per output pixel,
        and its weight in [0, 0.5] (0 outside the feathered bands). All three or none.
    info : dict
        Scalars of the analysis (``block_h``, ``block_w``, ``overlap_y``, ``overlap_x``,
        ``rank``, ...), stored as attributes.
    """

    source_map: np.ndarray
    labels: np.ndarray
    block_sources: np.ndarray
    block_positions: np.ndarray
    singular_values: np.ndarray
    rank_error: np.ndarray
    gain: np.ndarray | None = None
    blend_map: np.ndarray | None = None
    blend_labels: np.ndarray | None = None
    blend_weight: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @property
    def size(self) -> tuple[int, int]:
        """``(height, width)`` of the output canvas (the file stores them as attributes ``width`` and ``height``)."""
        return int(self.labels.shape[0]), int(self.labels.shape[1])

    @property
    def n_blocks(self) -> int:
        return int(self.block_sources.shape[0])

    @property
    def block(self) -> tuple[int, int]:
        """``(block_h, block_w)``."""
        return int(self.info["block_h"]), int(self.info["block_w"])

    def summary(self) -> str:
        """One line: canvas, blocks, the rank of the comparisons and its error."""
        info = self.info
        h, w = self.size
        return (
            f"{w}x{h} canvas from {self.n_blocks} blocks of {self.block[1]}x{self.block[0]}, "
            f"rank-{info.get('rank')} SVD error {100 * info.get('rank_error', 0):.2f}% "
            f"(comparing {info.get('compare_width')} instead of {info.get('full_width')} values per pixel)"
        )


def write(group: h5py.Group, model: QuiltModel) -> None:
    h, w = model.labels.shape
    group.create_dataset(
        "source_map", data=np.asarray(model.source_map, np.int32), chunks=(min(h, 256), w, 2), compression="lzf"
    )
    group.create_dataset("labels", data=np.asarray(model.labels, np.int32), chunks=(min(h, 256), w), compression="lzf")
    group.create_dataset("block_sources", data=np.asarray(model.block_sources, np.int32))
    group.create_dataset("block_positions", data=np.asarray(model.block_positions, np.int32))
    group.create_dataset("singular_values", data=np.asarray(model.singular_values, np.float64))
    group.create_dataset("rank_error", data=np.asarray(model.rank_error, np.float64))
    if model.gain is not None:
        group.create_dataset(
            "gain",
            data=np.asarray(model.gain, np.float32),
            chunks=(min(h, 256), w, model.gain.shape[2]),
            compression="lzf",
        )
    blend = (model.blend_map, model.blend_labels, model.blend_weight)
    if any(a is not None for a in blend):
        if any(a is None for a in blend):
            raise InvalidArgumentError("blend_map, blend_labels and blend_weight go together: give all three or none")
        group.create_dataset(
            "blend_map", data=np.asarray(model.blend_map, np.int32), chunks=(min(h, 256), w, 2), compression="lzf"
        )
        group.create_dataset(
            "blend_labels", data=np.asarray(model.blend_labels, np.int32), chunks=(min(h, 256), w), compression="lzf"
        )
        group.create_dataset(
            "blend_weight", data=np.asarray(model.blend_weight, np.float32), chunks=(min(h, 256), w), compression="lzf"
        )
    group.attrs["width"] = int(w)
    group.attrs["height"] = int(h)
    group.attrs["n_blocks"] = model.n_blocks
    for key, value in model.info.items():
        if key not in ("width", "height", "n_blocks"):
            group.attrs[key] = value


def read(group: h5py.Group, check: Checker, source: SourceInfo) -> QuiltModel:
    path = group.name
    w = check.attr(group, "width", int)
    h = check.attr(group, "height", int)
    nb = check.attr(group, "n_blocks", int)
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
        check.fail(path, f"implausible canvas size {w}x{h}")
    if not 1 <= nb <= h * w:
        check.fail(path + "@n_blocks", f"{nb} out of range 1..{h * w}")
    bh = check.attr(group, "block_h", int)
    bw = check.attr(group, "block_w", int)
    if not (1 <= bh <= source.height and 1 <= bw <= source.width):
        check.fail(path + "@block_h", f"block {bw}x{bh} does not fit the {source.width}x{source.height} source")
    ds = check.dataset
    smap = ds(group, "source_map", kind="iu", shape=(h, w, 2))
    labels = ds(group, "labels", kind="iu", shape=(h, w))
    bsrc = ds(group, "block_sources", kind="iu", shape=(nb, 2))
    bpos = ds(group, "block_positions", kind="iu", shape=(nb, 2))
    rank = min(source.height * source.width, source.n_frames * source.channels)
    sv = ds(group, "singular_values", kind="f", shape=(range(rank + 1),))
    err = ds(group, "rank_error", kind="f", shape=(sv.shape[0],))
    check.index_range(path + "/source_map", smap[..., 0], source.height)
    check.index_range(path + "/source_map", smap[..., 1], source.width)
    check.index_range(path + "/labels", labels, nb)
    check.index_range(path + "/block_sources", bsrc[:, 0], source.height - bh + 1)
    check.index_range(path + "/block_sources", bsrc[:, 1], source.width - bw + 1)
    if bpos.size and (bpos.min() < 0 or bpos[:, 0].max() >= h or bpos[:, 1].max() >= w):
        check.fail(path + "/block_positions", f"holds positions outside the {w}x{h} canvas")
    if sv.size and (sv.min() < 0 or np.any(np.diff(sv) > 1e-9 * max(float(sv[0]), 1.0))):
        check.fail(path + "/singular_values", "must be non-negative and descending")
    if err.size and (err.min() < 0 or err.max() > 1 + 1e-9 or np.any(np.diff(err) > 1e-9)):
        check.fail(path + "/rank_error", "must lie in [0, 1] and not increase with the rank")
    gain = None
    if "gain" in group:
        gain = ds(group, "gain", kind="f", shape=(h, w, source.channels))
        if gain.size and (gain.min() <= 0 or gain.max() > MAX_GAIN):
            check.fail(path + "/gain", f"values must lie in (0, {MAX_GAIN:g}]")
    blend: list[np.ndarray | None] = [None, None, None]
    present = [n in group for n in ("blend_map", "blend_labels", "blend_weight")]
    if any(present):
        if not all(present):
            check.fail(path, "blend_map, blend_labels and blend_weight must all be present or all absent")
        bmap = ds(group, "blend_map", kind="iu", shape=(h, w, 2))
        blab = ds(group, "blend_labels", kind="iu", shape=(h, w))
        bwt = ds(group, "blend_weight", kind="f", shape=(h, w))
        check.index_range(path + "/blend_map", bmap[..., 0], source.height)
        check.index_range(path + "/blend_map", bmap[..., 1], source.width)
        check.index_range(path + "/blend_labels", blab, nb)
        if bwt.size and (bwt.min() < 0 or bwt.max() > 0.5):
            check.fail(path + "/blend_weight", "values must lie in [0, 0.5]")
        blend = [
            bmap.astype(np.int32, copy=False),
            blab.astype(np.int32, copy=False),
            bwt.astype(np.float32, copy=False),
        ]
    info = check.info(group)
    return QuiltModel(
        source_map=smap.astype(np.int32, copy=False),
        labels=labels.astype(np.int32, copy=False),
        block_sources=bsrc.astype(np.int32, copy=False),
        block_positions=bpos.astype(np.int32, copy=False),
        singular_values=sv.astype(np.float64, copy=False),
        rank_error=err.astype(np.float64, copy=False),
        gain=None if gain is None else gain.astype(np.float32, copy=False),
        blend_map=blend[0],
        blend_labels=blend[1],
        blend_weight=blend[2],
        info=info,
    )
