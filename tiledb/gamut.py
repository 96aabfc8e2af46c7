"""The source's colour set as a nearest-colour map (the optional ``gamut`` subgroup of ``lds``
and ``mixture``).

A projection ``mean + basis x state`` can leave the colours the clip showed: where a red edge
moves over blue sky, a state past the sky's gives the opposite of red (cyan). The map sends
each colour bin (8 levels per channel, ``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)``) to the
nearest bin of the source's colour set (itself for a bin in the set); the player clamps a
pixel whose bin is outside into that one, channel by channel (the bin's closest colour).
Colour (three-channel) sources only: a grey projection cannot take a hue. Databases written
before it play without it.

The optional ``local`` subgroup (format 1.7, versioned on its own) holds a colour set per region
of the frame (squares of ``block`` pixels): a projection's low-rank mix can put a colour of the
clip where the clip never showed it (the flag's green-and-white mix as a teal haze over the
stone tower). Where a region never held a pixel's bin, the region's bin for it is the one
``nearest[region, cell]`` names for its 16-level cell ``(r >> 4) * 256 + (g >> 4) * 16 +
(b >> 4)``. Each region's set lies within the clip's; the player applies the sets, each pixel those of its
four nearest regions blended by its position between their centres (``player/engines/projection.py``,
``snap_local``: no edge where two regions meet), then the global map to the blend, which can lie
outside every one of them; a reader that predates them plays the global map alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from ._check import Checker
from ._parts import exact_dtype, open_part, write_part
from .source import SourceInfo

#: Version of the ``gamut`` part this reader understands; a newer part is ignored (it is optional).
GAMUT_VERSION = 1
GROUP = "gamut"
#: Version of the ``local`` subgroup this reader understands; a newer one is ignored.
LOCAL_VERSION = 1
LOCAL = "local"
#: The largest region side a reader accepts (a region larger than the frame is the whole frame).
MAX_BLOCK = 1 << 16
#: The most regions a frame's local sets may have (the analyzer doubles the side until they fit):
#: the player lays out per region and per group of four what a reader bounds here.
MAX_REGIONS = 1024
#: Cells of 16 levels per channel a region's nearest map is indexed by.
CELLS = 1 << 12
#: Bits per channel of a colour bin, and the number of bins.
BIN_BITS = 5
COLOUR_BINS = 1 << (3 * BIN_BITS)


@dataclass
class LocalGamut:
    """Per region of the frame, its colour set and each 16-level cell's nearest bin in it.

    Attributes
    ----------
    block : int
        Side in pixels of a region (squares, row-major; the last row and column may be narrower).
    inside : (regions, 4096) uint8
        The region's set, one bit per colour bin: bin ``b`` is in it when bit ``b & 7`` of
        ``inside[region, b >> 3]`` is set.
    nearest : (regions, 4096) uint16
        For each cell ``(r >> 4) * 256 + (g >> 4) * 16 + (b >> 4)``, a bin of the region's set
        (the set's nearest to the cell's lowest bin).
    """

    block: int
    inside: np.ndarray
    nearest: np.ndarray

    def regions(self, height: int, width: int) -> tuple[int, int]:
        """(rows, columns) of regions over a ``height`` x ``width`` frame."""
        return -(-height // self.block), -(-width // self.block)


@dataclass
class GamutModel:
    """The source's colour set, as each colour bin's nearest bin in it.

    Attributes
    ----------
    nearest : (32768,) uint16
        For each bin ``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)``, the nearest bin (Euclidean,
        in bins) of the source's colour set: the bin itself where the source holds it.
    info : dict
        Scalars (``colours``: bins in the set; ``min_pixels``: the pixels of the clip a bin held
        to be in it).
    local : LocalGamut, optional
        The colour set of each region of the frame (None: databases without it).
    """

    nearest: np.ndarray
    info: dict = field(default_factory=dict)
    local: LocalGamut | None = None

    @property
    def colours(self) -> int:
        """Bins in the colour set."""
        return int(np.count_nonzero(self.nearest == np.arange(COLOUR_BINS)))


def describe(model: GamutModel | None) -> dict:
    """Facts for a model's ``describe()``."""
    if model is None:
        return {"gamut": False}
    facts = {"gamut": True, "gamut_colours": model.colours}
    if model.local is not None:
        facts["gamut_local_block"] = model.local.block
    return facts


def write(parent: h5py.Group, model: GamutModel | None) -> None:
    """Store ``model`` as ``parent/gamut`` (nothing when None)."""
    if model is None:
        return
    write_part(parent, GROUP, GAMUT_VERSION, {"nearest": np.asarray(model.nearest, np.uint16)}, attrs=model.info)
    if model.local is not None:
        loc = model.local
        data = {"inside": np.asarray(loc.inside, np.uint8), "nearest": np.asarray(loc.nearest, np.uint16)}
        write_part(parent[GROUP], LOCAL, LOCAL_VERSION, data, attrs={"block": int(loc.block)})


def read(parent: h5py.Group, check: Checker, source: SourceInfo) -> GamutModel | None:
    """The validated ``parent/gamut`` part, or None when absent, of a newer version or on a grey source."""
    g = open_part(parent, GROUP, GAMUT_VERSION, check)
    if g is None or source.channels != 3:
        return None
    nearest = check.dataset(g, "nearest", kind="u", shape=(COLOUR_BINS,))
    path = g.name + "/nearest"
    exact_dtype(check, path, nearest, np.uint16)
    if int(nearest.max()) >= COLOUR_BINS:
        check.fail(path, f"a bin outside 0..{COLOUR_BINS - 1}")
    if (nearest[nearest] != nearest).any():
        check.fail(path, "a bin maps to a bin outside the colour set (a target must map to itself)")
    stated = check.attr(g, "colours", int)
    colours = int(np.count_nonzero(nearest == np.arange(COLOUR_BINS)))
    if colours != stated:  # a damaged map (zeroed, say) would snap every frame to a few colours
        check.fail(path, f"holds {colours} colours where the part says {stated}")
    info = check.info(g, skip=("version",))
    return GamutModel(nearest=np.ascontiguousarray(nearest), info=info, local=_read_local(g, check, source, nearest))


def _read_local(g: h5py.Group, check: Checker, source: SourceInfo, nearest: np.ndarray) -> LocalGamut | None:
    """The validated ``gamut/local`` subgroup, or None when absent or of a newer version."""
    loc = open_part(g, LOCAL, LOCAL_VERSION, check)
    if loc is None:
        return None
    block = check.attr(loc, "block", int)
    if not 1 <= block <= MAX_BLOCK:
        check.fail(loc.name + "@block", f"{block} is not a region side (1..{MAX_BLOCK})")
    model = LocalGamut(block=block, inside=np.empty(0), nearest=np.empty(0))
    rows, cols = model.regions(source.height, source.width)
    if rows * cols > MAX_REGIONS:
        check.fail(
            loc.name + "@block",
            f"{block} gives the frame {rows * cols} regions (at most {MAX_REGIONS})",
        )
    model.inside = check.dataset(loc, "inside", kind="u", shape=(rows * cols, CELLS))
    model.nearest = check.dataset(loc, "nearest", kind="u", shape=(rows * cols, CELLS))
    for name, dtype in (("inside", np.uint8), ("nearest", np.uint16)):
        exact_dtype(check, f"{loc.name}/{name}", getattr(model, name), dtype)
    if int(model.nearest.max()) >= COLOUR_BINS:
        check.fail(loc.name + "/nearest", f"a bin outside 0..{COLOUR_BINS - 1}")
    bits = local_bits(model)
    if not bits[np.arange(rows * cols)[:, None], model.nearest].all():
        check.fail(loc.name + "/nearest", "a cell maps to a bin outside its region's set")
    if (bits & (nearest != np.arange(COLOUR_BINS))).any():
        check.fail(loc.name + "/inside", "a region holds a bin outside the clip's colour set")
    model.inside, model.nearest = np.ascontiguousarray(model.inside), np.ascontiguousarray(model.nearest)
    return model


def local_bits(model: LocalGamut) -> np.ndarray:
    """``model.inside`` unpacked: bool ``(regions, 32768)``, True where the region holds the bin."""
    return np.unpackbits(model.inside, axis=1, bitorder="little").astype(bool)
