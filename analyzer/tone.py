"""Learning a projection model's tone map (the ``tone`` part of ``lds`` and ``mixture``,
:mod:`dynatex.tiledb.tone`): each channel's levels Gaussianised, so that a Gaussian model of a
clip whose values pile at the ends of the range keeps its energy.

A Gaussian state spreads every pixel's values symmetrically about its mean. Where a clip's values
pile at 0 and 255 (flames on a black background: the background at 0, the cores at 255), much of
that spread lies beyond the range and is cut off at the store: on a 720p flame clip 14% of the
output's values saturate and the output keeps 0.65 of the clip's energy where the unclipped
values hold 0.81. Learned on ``forward[c, level]`` instead (the channel's mean plus its standard
deviation times the normal quantile of the level's mid-rank in the channel's histogram, the
quantile held to +-:data:`Z_MAX`), the model's values are about Gaussian, and the player maps
them back through the same curve (:class:`~dynatex.player.engines.tone.ToneLookup`): a state far
out lands on the clip's brightest or darkest levels instead of past them.

:func:`choose` learns a map where a Gaussian with each value's own mean and variance over the clip
would put more than :data:`SATURATION_SHARE` of the values outside 0..255 (:func:`saturation_share`);
on clips that are not so skewed the values stay as they are.

A Gaussian draw seen through the map back to levels holds less variance than the training frames
with the same tone covariance: a pixel of the clip is dark most of the time and bright now and
then, at the flat ends of the map, where a Gaussian draw of its mean and variance spends much of
its time in the steep middle. :func:`gain_for` finds the factor on a model's variances that gives
its draws, in levels, the variance its training reconstructions have there (:func:`level_gain`
for an lds; a mixture's components each their own Gaussian).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.special import ndtr, ndtri

from ..errors import InvalidArgumentError
from ..framestats import CHUNK, even_sample
from ..player.engines.tone import ToneLookup
from ..tiledb.tone import BINS, LEVELS, ToneModel

#: A model is learned on tone values where a Gaussian per value would saturate more than this share.
SATURATION_SHARE = 0.05
#: The normal quantiles of the map are held to +-Z_MAX standard deviations.
Z_MAX = 4.0
#: Equally likely values (normal quantiles) a Gaussian tone value's variance in levels is taken over.
QUANTILES = 64
#: Pixels :func:`gain_for` measures on (evenly spaced; all where there are fewer).
GAIN_PIXELS = 1 << 15
#: The gain :func:`gain_for` looks for lies in ``1 / MAX_GAIN .. MAX_GAIN``.
MAX_GAIN = 8.0
#: Halvings of that range (in log gain) the search takes: 12 find the gain to 0.1%.
GAIN_STEPS = 12
#: Bins the ramp that keeps the map's steps at least a lookup bin wide is sized for (< BINS: a margin).
_RAMP_BINS = BINS - 512


def saturation_share(frames: np.ndarray) -> float:
    """Share of the values of ``frames`` ``(T, H, W, C)`` uint8 that a Gaussian with each value's
    own mean and variance over the clip puts outside ``-0.5 .. 255.5``.

    >>> flat = np.full((4, 2, 2, 3), 128, np.uint8); flat[::2] = 130
    >>> saturation_share(flat)
    0.0
    >>> ends = np.zeros((4, 2, 2, 3), np.uint8); ends[::2] = 255
    >>> round(saturation_share(ends), 3)
    0.315
    """
    t = frames.shape[0]
    flat = frames.reshape(t, -1)
    total = np.zeros(flat.shape[1])
    squares = np.zeros(flat.shape[1])
    for lo in range(0, t, CHUNK):
        block = flat[lo : lo + CHUNK].astype(np.float64)
        total += block.sum(axis=0)
        squares += np.einsum("ij,ij->j", block, block)
    mean = total / t
    sd = np.sqrt(np.maximum(squares / t - mean**2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        below = np.where(sd > 0, ndtr((-0.5 - mean) / sd), 0.0)
        above = np.where(sd > 0, ndtr((mean - 255.5) / sd), 0.0)
    return float(np.mean(below + above))


def learn_tone(frames: np.ndarray, share: float | None = None) -> ToneModel:
    """The tone map of ``frames`` ``(T, H, W, C)`` uint8: per channel, ``forward[c, level]``
    strictly increasing, its steps at least ``span / BINS`` (the part's rule); ``share``: the
    clip's :func:`saturation_share`, when the caller has it.

    Two levels alone, half the values each, lie at the quartiles of a Gaussian (+-0.67 standard
    deviations), so that the model's spread about them reaches the ends of the range:

    >>> clip = np.zeros((10, 4, 4, 1), np.uint8); clip[5:] = 255
    >>> fwd = learn_tone(clip).forward[0]
    >>> bool(np.all(np.diff(fwd) > 0)), round(float(fwd[0])), round(float(fwd[255]))
    (True, 35, 220)
    """
    c = frames.shape[-1]
    counts = np.zeros((c, LEVELS), np.int64)
    for lo in range(0, frames.shape[0], CHUNK):
        block = frames[lo : lo + CHUNK].reshape(-1, c)
        for ch in range(c):
            counts[ch] += np.bincount(block[:, ch], minlength=LEVELS)
    levels = np.arange(LEVELS, dtype=np.float64)
    forward = np.empty((c, LEVELS))
    for ch in range(c):
        h = counts[ch].astype(np.float64)
        n = h.sum()
        mean = float(h @ levels / n)
        sd = max(float(np.sqrt(h @ (levels - mean) ** 2 / n)), 1.0)
        rank = (np.cumsum(h) - h / 2) / n
        z = np.clip(ndtri(np.clip(rank, 0.5 / n, 1 - 0.5 / n)), -Z_MAX, Z_MAX)
        curve = mean + sd * z
        step = (curve[-1] - curve[0]) / _RAMP_BINS
        forward[ch] = curve + step * (levels - 127.5)
    info = {"saturation_share": saturation_share(frames) if share is None else float(share)}
    return ToneModel(forward=forward.astype(np.float32), info=info)


def choose(frames: np.ndarray | None, tone: str) -> ToneModel | None:
    """The tone map to learn ``frames`` on for the ``tone`` parameter: "on" always, "off" never,
    "auto" where :func:`saturation_share` exceeds :data:`SATURATION_SHARE`. ``frames`` None (a
    streamed clip, never in memory): no map, and "on" is refused."""
    if frames is None:
        if tone == "on":
            raise InvalidArgumentError("tone='on' needs the clip in memory; a streamed clip is learned on its levels")
        return None
    if tone == "off":
        return None
    share = saturation_share(frames)
    if tone == "auto" and share <= SATURATION_SHARE:
        return None
    return learn_tone(frames, share)


def to_tone(frames: np.ndarray, tone: ToneModel) -> np.ndarray:
    """``frames`` ``(T, H, W, C)`` uint8 as tone values, float32 ``(T, H * W * C)``."""
    t, c = frames.shape[0], frames.shape[-1]
    out = np.empty((t, frames[0].size), np.float32)
    view = out.reshape(t, -1, c)
    src = frames.reshape(t, -1, c)
    for ch in range(c):
        np.take(tone.forward[ch], src[..., ch], out=view[..., ch])
    return out


Reconstruct = Callable[[int, int], np.ndarray]


def levels_of(reconstruct: Reconstruct, tone: ToneModel | None) -> Reconstruct:
    """A model's reconstruction ``reconstruct(t0, t1)`` (float32 ``(t1 - t0, P)``) in levels, as the
    player stores them: through ``tone``'s lookup (``reconstruct`` itself when None)."""
    if tone is None:
        return reconstruct
    lookup = ToneLookup(tone)
    return lambda t0, t1: lookup.levels(reconstruct(t0, t1))


def _levels(tone: ToneModel, values: np.ndarray) -> np.ndarray:
    """``values`` ``(k, P)`` tone values (``P`` interleaved values of ``tone``'s channels a row)
    as levels, float64, through the map interpolated between levels (held to 0..255): the
    player's lookup without its rounding, which would make the integral over a Gaussian a sum of steps."""
    c = tone.channels
    out = np.empty(values.shape, np.float64)
    levels = np.arange(LEVELS, dtype=np.float64)
    for ch in range(c):
        out[:, ch::c] = np.interp(values[:, ch::c], tone.forward[ch].astype(np.float64), levels)
    return out


def pixel_sample(tone: ToneModel, values: int) -> np.ndarray:
    """The columns of up to :data:`GAIN_PIXELS` pixels (evenly spaced, each with all of ``tone``'s
    channels) among ``values`` interleaved values, where :func:`gain_for` measures."""
    c = tone.channels
    return (even_sample(values // c, GAIN_PIXELS)[:, None] * c + np.arange(c)).ravel()


def gain_for(
    tone: ToneModel,
    train: tuple[np.ndarray, np.ndarray, np.ndarray],
    means: np.ndarray,
    sds: np.ndarray,
    weights: np.ndarray | None = None,
) -> float:
    """The factor on a model's variances that gives its draws, mapped back to levels, the mean
    variance per value there that its training reconstructions have (``train`` = ``(coefs, rows,
    offset)``: ``coefs @ rows + offset``, ``(T, P)`` tone values, taken :data:`CHUNK` frames at a
    time): the draws a mixture, per value, of Gaussians ``means`` and ``sds`` (``(S, P)``, their
    ``weights`` ``(S,)``, equal where None), each spread over :data:`QUANTILES` equally likely
    values. The draws' variance grows with the gain; the search (to 0.1%) is held to
    ``1 / MAX_GAIN .. MAX_GAIN``, and returns a bound where even it falls short or overshoots."""
    target = _level_variance(tone, *train)
    w = np.full(len(means), 1 / len(means)) if weights is None else np.asarray(weights, np.float64) / np.sum(weights)
    z = ndtri((np.arange(QUANTILES) + 0.5) / QUANTILES)[:, None]
    z /= z.std()  # the quantiles' own spread falls short of 1 in the tails

    def variance(gain: float) -> float:
        first = np.zeros(means.shape[1])
        second = np.zeros(means.shape[1])
        for m, sd, ws in zip(means, sds, w):
            levels = _levels(tone, m + np.sqrt(gain) * z * sd)
            first += ws * levels.mean(axis=0)
            second += ws * (levels**2).mean(axis=0)
        return float((second - first**2).mean())

    if target <= 0.0 or variance(1.0) <= 0.0:
        return 1.0
    lo, hi = np.log(1 / MAX_GAIN), np.log(MAX_GAIN)
    for _ in range(GAIN_STEPS):
        mid = (lo + hi) / 2
        if variance(float(np.exp(mid))) < target:
            lo = mid
        else:
            hi = mid
    return float(np.exp((lo + hi) / 2))


def level_gain(mean: np.ndarray, basis: np.ndarray, cov: np.ndarray, states: np.ndarray, tone: ToneModel) -> float:
    """The factor on the state covariance ``cov`` (``(n, n)``) of a model ``mean + basis.T @ x``
    (``basis`` ``(n, P)``, tone values, ``P`` interleaved values of ``tone``'s channels) that gives
    its Gaussian draws, mapped back to levels, the mean variance there that the reconstructions of
    its training ``states`` (``(n, T)``) have (:func:`gain_for`, on :func:`pixel_sample`).

    On a linear stretch of the map the gain is 1, where the map's flat ends squeeze a draw it is more:

    >>> rng = np.random.default_rng(0)
    >>> basis = np.linalg.qr(rng.standard_normal((64, 2)))[0].T.astype(np.float32)
    >>> states = rng.standard_normal((2, 4000)) * 200
    >>> cov, mean = states @ states.T / 4000, np.full(64, 150.0, np.float32)
    >>> linear = ToneModel(np.linspace(-300.0, 600.0, 256, dtype=np.float32)[None])
    >>> round(level_gain(mean, basis, cov, states, linear), 2)
    1.0
    >>> bimodal = (np.sign(states) * np.abs(states) ** 0.25) * 200 / 4
    >>> steep = ToneModel(np.linspace(100.0, 200.0, 256, dtype=np.float32)[None])
    >>> level_gain(mean, basis, bimodal @ bimodal.T / 4000, bimodal, steep) > 1.1
    True
    """
    cols = pixel_sample(tone, basis.shape[1])
    rows, m = basis[:, cols].astype(np.float64), mean[cols].astype(np.float64)
    sd = np.sqrt(np.maximum(np.einsum("ip,ij,jp->p", rows, cov, rows), 0.0))
    return gain_for(tone, (states.T, rows, m), m[None], sd[None])


def _level_variance(tone: ToneModel, coefs: np.ndarray, rows: np.ndarray, offset: np.ndarray) -> float:
    """The mean over values of the variance in levels of ``coefs @ rows + offset`` over its rows."""
    first = np.zeros(rows.shape[1])
    second = np.zeros(rows.shape[1])
    for t0 in range(0, len(coefs), CHUNK):
        levels = _levels(tone, coefs[t0 : t0 + CHUNK] @ rows + offset)
        first += levels.sum(axis=0)
        second += (levels * levels).sum(axis=0)
    first /= len(coefs)
    return float((second / len(coefs) - first * first).mean())
