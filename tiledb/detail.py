"""The fine detail and colour range of a projection model (the optional ``detail`` subgroup of
``lds`` and ``mixture``).

A projection model keeps only its top components; the rest of the clip (the truncation
residual: fine, fast detail) is stored as a noise volume with the residual's own colour
axes and spatio-temporal power spectrum, wrapping in time, y and x, and a per-pixel gain.
The player adds it to the projected frame and holds every pixel to the colour range the
source showed there. Databases written before it play without it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from ._check import Checker
from ._parts import exact_dtype, open_part, write_part
from .source import SourceInfo

#: Version of the ``detail`` part this reader understands; a newer part is ignored (it is optional).
DETAIL_VERSION = 1
GROUP = "detail"
#: Colour bins: 8 levels per channel.
COLOUR_BINS = 32**3
#: Longest noise volume, in frames.
MAX_VOLUME_FRAMES = 256
#: Residual share above which ``describe()`` warns that the detail is noise standing in for structure.
WARN_RESIDUAL = 0.2
#: Largest per-pixel gain: a gain times the int8 range stays within a few pixel ranges.
MAX_GAIN = 16.0


@dataclass
class DetailModel:
    """Noise volume, gain and colour range added to a projection model's frames.

    Attributes
    ----------
    volume : (Tv, Hv, Wv, C) int8
        Zero-mean noise in pixel colour space, periodic in all three axes.
    gain : (H, W) float32
        Per-pixel factor turning a volume value into pixel units (the residual's local level).
    low, high : (H, W, C) uint8
        The colour range of each pixel in the source (per channel), ``low <= high``.
    colours : (32768,) uint8
        1 for each colour bin (``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)``) the source shows, or
        a neighbouring bin does; a pixel whose detail would leave this set gets none.
    info : dict
        Scalars (``residual_energy``: the residual's share of the clip's variance, ...).
    """

    volume: np.ndarray
    gain: np.ndarray
    low: np.ndarray
    high: np.ndarray
    colours: np.ndarray
    info: dict = field(default_factory=dict)


def describe(model: DetailModel | None, info: dict | None = None) -> dict:
    """Facts for a model's ``describe()``: the residual's share, and a warning where it is large or
    where the analysis left the detail out (the model's ``info`` says so: ``detail_coarse_share``)."""
    if model is None:
        coarse = (info or {}).get("detail_coarse_share")
        if coarse is None:
            return {"detail": False}
        return {
            "detail": False,
            "warning": f"no detail part: {float(coarse):.0%} of what the projection leaves out lies at "
            "wavelengths over a quarter of the noise volume's side (structure, not fine detail), which "
            "would repeat across the frame as blobs; the output stays smoother than the clip",
        }
    share = float(model.info.get("residual_energy", 0.0))
    out = {"detail": True, "detail_residual_energy": round(share, 4)}
    if share > WARN_RESIDUAL:
        out["warning"] = (
            f"the projection keeps {1 - share:.0%} of the clip's variance; the detail part adds the rest "
            "as a noise texture with its spectrum and colours: fine grain and motion, not structure "
            "such as foam or sharp moving edges"
        )
    return out


def write(parent: h5py.Group, model: DetailModel | None) -> None:
    """Store ``model`` as ``parent/detail`` (nothing when None)."""
    if model is None:
        return
    arrays = {
        "volume": np.asarray(model.volume, np.int8),
        "gain": np.asarray(model.gain, np.float32),
        "low": np.asarray(model.low, np.uint8),
        "high": np.asarray(model.high, np.uint8),
        "colours": np.asarray(model.colours, np.uint8),
    }
    write_part(parent, GROUP, DETAIL_VERSION, arrays, attrs=model.info, rows=("volume",))


def read(parent: h5py.Group, check: Checker, source: SourceInfo) -> DetailModel | None:
    """The validated ``parent/detail`` part, or None when absent or of a newer version."""
    g = open_part(parent, GROUP, DETAIL_VERSION, check)
    if g is None:
        return None
    h, w, c = source.height, source.width, source.channels
    ds = check.dataset
    vol = ds(
        g, "volume", kind="i", shape=(range(1, MAX_VOLUME_FRAMES + 1), range(1, h + 1), range(1, w + 1), c), read=False
    )
    exact_dtype(check, vol.name, vol, np.int8)
    check.attr(g, "residual_energy", float, None)  # describe() shows it as a number
    tv, hv, wv = vol.shape[:3]
    model = DetailModel(
        volume=ds(g, "volume", kind="i", shape=(tv, hv, wv, c)),
        gain=ds(g, "gain", kind="f", shape=(h, w)),
        low=ds(g, "low", kind="u", shape=(h, w, c)),
        high=ds(g, "high", kind="u", shape=(h, w, c)),
        colours=ds(g, "colours", kind="u", shape=(COLOUR_BINS,)),
        info=check.info(g, skip=("version",)),
    )
    for name in ("low", "high", "colours"):
        exact_dtype(check, f"{g.name}/{name}", getattr(model, name), np.uint8)
    if model.colours.max() > 1:
        check.fail(g.name + "/colours", "must be uint8 flags, 0 or 1")
    if not (model.gain.min() >= 0 and model.gain.max() <= MAX_GAIN):
        check.fail(g.name + "/gain", f"values outside 0..{MAX_GAIN:g}")
    if (model.low > model.high).any():
        check.fail(g.name + "/low", "exceeds high at some pixel: a colour range must have low <= high")
    model.gain = np.ascontiguousarray(model.gain, np.float32)
    return model
