"""The per-channel tone map of a projection model (the ``tone`` subgroup of ``lds`` and ``mixture``).

A Gaussian model of a clip whose values pile up at 0 and 255 (a dark background, white flames)
saturates its output and loses energy. A model with a tone part was learned on each channel's
levels Gaussianised: level ``l`` of channel ``c`` became ``forward[c, l]``, strictly increasing in
``l`` and on a pixel-like scale (the channel's mean plus its standard deviation times a normal
quantile clipped to +-4, so values may lie somewhat outside 0..255). The model's mean, basis and
states are in those tone units. The player maps a projected value ``y`` of channel ``c`` back to
a level through :data:`BINS` uniform bins spanning ``[forward[c, 0], forward[c, 255]]``: bin
``floor((y - forward[c, 0]) * BINS / (forward[c, 255] - forward[c, 0]))`` clamped to
``0..BINS - 1``, whose level is the level nearest the bin's centre (thresholds halfway between
neighbouring ``forward`` values; :func:`lookup` builds the table).

Unlike the optional parts (``detail``, ``gamut``: a reader that meets a newer version plays
without them), the tone part cannot be left out: a model learned on tone values is garbage
without its map. A reader refuses a part of a version newer than :data:`TONE_VERSION`
(:class:`~.errors.TileDBVersionError`), and a file holding one is format 2.x, whose major
1.x readers refuse.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from . import schema
from ._check import Checker
from ._parts import exact_dtype, open_required_part, write_part
from .source import SourceInfo

#: Version of the ``tone`` part this reader understands; a newer part is refused (it is required).
TONE_VERSION = 1
GROUP = schema.PART_TONE
#: Levels of a channel.
LEVELS = 256
#: Bins per channel of the player's lookup from tone values back to levels (part of the format:
#: it bounds the steps of ``forward``).
BINS = 4096
#: Largest magnitude of a tone value: far past any clipped Gaussian of levels, far below overflow.
MAX_VALUE = 1e4
#: Least span of a channel's map (the analysis makes 8 at least): a tinier one overflows the
#: lookup's scale ``BINS / span`` in float32.
MIN_SPAN = 1.0


@dataclass
class ToneModel:
    """Each channel's levels Gaussianised, the scale a projection model was learned on.

    Attributes
    ----------
    forward : (C, 256) float32
        ``forward[c, l]``: the tone value of level ``l`` of channel ``c``, strictly increasing in
        ``l``, each step at least ``(forward[c, 255] - forward[c, 0]) / BINS``.
    info : dict
        Scalars (``saturation_share``: the share of the clip's values a Gaussian with each value's
        own mean and variance puts outside 0..255, what made the analysis learn on tone values).
    """

    forward: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def channels(self) -> int:
        return int(self.forward.shape[0])


def describe(tone: ToneModel | None) -> dict:
    """Facts for a model's ``describe()`` (none without a tone map)."""
    if tone is None:
        return {}
    facts: dict = {"tone": "gaussianised per channel"}
    if "saturation_share" in tone.info:
        facts["tone_saturation_share"] = round(float(tone.info["saturation_share"]), 4)
    return facts


def summary(tone: ToneModel | None) -> str:
    """What a model's one-line summary adds for its tone map ("" without one)."""
    return "" if tone is None else ", learned on Gaussianised levels (tone map)"


def write(parent: h5py.Group, tone: ToneModel | None) -> None:
    """Store ``tone`` as ``parent/tone`` (nothing when None)."""
    if tone is None:
        return
    write_part(parent, GROUP, TONE_VERSION, {"forward": np.asarray(tone.forward, np.float32)}, attrs=tone.info)


def read(parent: h5py.Group, check: Checker, source: SourceInfo) -> ToneModel | None:
    """The validated ``parent/tone`` part, or None when absent; a newer version is refused."""
    g = open_required_part(parent, GROUP, TONE_VERSION, check)
    if g is None:
        return None
    path = g.name + "/forward"
    forward = check.dataset(g, "forward", kind="f", shape=(source.channels, LEVELS))
    exact_dtype(check, path, forward, np.float32)
    problem = forward_problem(forward)
    if problem:
        check.fail(path, problem)
    check.attr(g, "saturation_share", float, None)  # describe() shows it as a number
    return ToneModel(forward=np.ascontiguousarray(forward), info=check.info(g, skip=("version",)))


def forward_problem(forward: np.ndarray) -> str | None:
    """What makes ``forward`` (``(C, 256)``, finite) no tone map, or None.

    Each step must be at least the channel's span over :data:`BINS`: then neighbouring thresholds
    of the lookup lie at least a bin apart, no bin holds two, and a value's level from the lookup
    is within one level of its exact nearest level, whatever bin rounding a backend makes.
    """
    f = np.asarray(forward, np.float64)
    if not np.abs(f).max() <= MAX_VALUE:
        return f"values reach {np.abs(f).max():.3g}, beyond +-{MAX_VALUE:g}"
    steps = np.diff(f, axis=1)
    if not steps.min() > 0:
        c, level = np.unravel_index(int(np.argmin(steps)), steps.shape)
        return f"is not strictly increasing in the level (channel {c}, levels {level} -> {level + 1})"
    span = f[:, -1] - f[:, 0]
    if not span.min() >= MIN_SPAN:
        return f"channel {int(np.argmin(span))} spans {span.min():.3g}, under {MIN_SPAN:g}"
    low = steps.min(axis=1) * BINS / (f[:, -1] - f[:, 0])
    if not low.min() >= 1:
        c = int(np.argmin(low))
        return (
            f"channel {c} has a step of {steps[c].min():.3g}, below its span over {BINS} bins "
            f"({(f[c, -1] - f[c, 0]) / BINS:.3g}): the player's lookup could miss a level"
        )
    return None


def lookup(tone: ToneModel) -> np.ndarray:
    """The player's table ``(C, BINS)`` uint8: each bin's level, the level nearest the bin's centre."""
    f = np.asarray(tone.forward, np.float64)
    lo, span = f[:, :1], f[:, -1:] - f[:, :1]
    centres = lo + (np.arange(BINS) + 0.5) * span / BINS
    thresholds = (f[:, 1:] + f[:, :-1]) / 2
    return np.stack([np.searchsorted(t, x, side="right") for t, x in zip(thresholds, centres)]).astype(np.uint8)


def mean_range(tone: ToneModel | None) -> tuple[float, float]:
    """The range a model's mean may lie in: the pixel range (or the tone map's values), widened by 1."""
    if tone is None:
        return -1.0, 256.0
    return float(tone.forward.min()) - 1, float(tone.forward.max()) + 1


def value_span(tone: ToneModel | None) -> float:
    """The span of a frame's values that bounds a state (a frame's distance from the mean is at
    most ``value_span * sqrt(P)``): 256 for pixels, the tone map's range where it is wider."""
    if tone is None:
        return 256.0
    return max(256.0, float(tone.forward.max()) - float(tone.forward.min()))


def check_mean(path: str, mean: np.ndarray, tone: ToneModel | None, check: Checker) -> None:
    """Refuse a model's ``mean`` outside :func:`mean_range`."""
    lo, hi = mean_range(tone)
    if mean.min() < lo or mean.max() > hi:
        where = "the 0..255 pixel range" if tone is None else f"the tone map's range ({lo + 1:.6g}..{hi - 1:.6g})"
        check.fail(path, f"values outside {where}")
