"""The source's colour set as a nearest-colour map (the optional ``gamut`` subgroup of ``lds``
and ``mixture``).

A projection ``mean + basis x state`` can leave the colours the clip showed: where a red edge
moves over blue sky, a state past the sky's gives the opposite of red (cyan). The map sends
each colour bin (8 levels per channel, ``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)``) to the
nearest bin of the source's colour set (itself for a bin in the set); the player clamps a
pixel whose bin is outside into that one, channel by channel (the bin's closest colour).
Colour (three-channel) sources only: a grey projection cannot take a hue. Databases written
before it play without it.
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
#: Bits per channel of a colour bin, and the number of bins.
BIN_BITS = 5
COLOUR_BINS = 1 << (3 * BIN_BITS)


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
    """

    nearest: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def colours(self) -> int:
        """Bins in the colour set."""
        return int(np.count_nonzero(self.nearest == np.arange(COLOUR_BINS)))


def describe(model: GamutModel | None) -> dict:
    """Facts for a model's ``describe()``."""
    if model is None:
        return {"gamut": False}
    return {"gamut": True, "gamut_colours": model.colours}


def write(parent: h5py.Group, model: GamutModel | None) -> None:
    """Store ``model`` as ``parent/gamut`` (nothing when None)."""
    if model is None:
        return
    write_part(parent, GROUP, GAMUT_VERSION, {"nearest": np.asarray(model.nearest, np.uint16)}, attrs=model.info)


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
    return GamutModel(nearest=np.ascontiguousarray(nearest), info=info)
