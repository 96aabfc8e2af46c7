"""The block grid a compressed clip carries, found and smoothed away before a projection model
learns from it (the ``deblock`` parameter of ``lds`` and ``mixture``).

A clip compressed by a block codec (MPEG-4, H.264) carries its transform's grid: luma blocks of
8 pixels, chroma blocks of 16 where the chroma is subsampled by two, starting at the frame's
corner. In the clip the grid is faint, because each block's error is consistent with its content
over time; a projection model learns it through its components and recombines them at random, so
its output shows squares whose levels do not match their neighbours' (blue and dark squares on a
flame clip's black ground, where the tone map spreads the dark levels apart).

Both steps work on the luma and on the chroma at half resolution (B - Y and R - Y averaged over
2 x 2 pixels), per axis, on the *excess step* at a pair of neighbours: the step between them less
the mean of the steps on either side, ``(q0 - p0) - ((p0 - p1) + (q1 - q0)) / 2``, zero on a
smooth ramp.

- :func:`detect_grid` measures, at each phase of an 8-pixel period, the median over the period's
  pixel pairs of the log ratio of the mean absolute step there (across frames and rows) to the
  steps beside it (three each side). A codec's grid puts the boundary phase well above the other
  seven (CHANGELOG.md has the ratios of the shared clips); a natural texture, whose statistics do
  not depend on the position, puts every phase near 1. The luma is also looked at with a 16-pixel
  period: an H.264 clip's flat areas are coded as whole 16 x 16 macroblocks, whose steps a
  16-pixel pass smooths first.
- :func:`deblock` maps the magnitude of each boundary's excess step through a quantile map that
  takes its distribution (over the sampled frames, per class of activity beside the pair: a flat
  dark patch has its own map) to the inside pairs', never growing it, scaled so that the
  boundaries' mean absolute step comes out as the inside's (up to the whole excess), and spreads
  what it removes as a ramp over half a block on each side, which removes exactly that much of
  the excess. The small steps of the codec's quantisation go; a real edge on a boundary (far out
  in the distribution's tail, where the two agree) keeps most of its step.

The model learns from the smoothed values in float; the detail part measures its residual
against them rounded. With a tone map the grid is smoothed in tone values, with quantile maps
measured there: where the map spreads the dark levels apart, a one-level step of the codec is a
step of tens of tone units to the model, and a channel at level 0 can ramp below the map's first
value there, where in levels it is held at 0 and the grid stays. The player is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidArgumentError
from ..framestats import CHUNK, LUMA, even_sample
from ..tiledb.tone import ToneModel
from .tone import to_tone

#: Period in pixels of the grids looked for (the luma's blocks; the chroma's, at half resolution).
PERIOD = 8
#: The boundaries of a codec's blocks lie after pixel 7 of each period: its grid starts at the
#: frame's corner (a clip cropped after decoding at an offset that is not a multiple of 8 keeps its
#: grid where it is not looked for).
PHASE = PERIOD - 1
#: Phases the boundaries' steps are compared with in the quantile map: inside the blocks, less the
#: middle (an H.264 4 x 4 transform's boundary).
INSIDE = (2, 4)
#: Classes of activity beside a pair (equally many boundaries each) that have quantile maps of their own.
CLASSES = 8
#: Steps beside a boundary that its step is compared with, each side.
SIDE = 3
#: A grid is found where the boundaries' median step ratio reaches this ...
MIN_RATIO = 1.15
#: ... and exceeds every other phase's by this factor.
MARGIN = 1.1
#: The largest ratio a description shows (a perfect synthetic grid's ratio is its steps over ~0).
MAX_SHOWN = 99.0
#: Frames the detection looks at (evenly spread over the clip).
SAMPLE_FRAMES = 32
#: Most of the maps' removal taken away (more than all of it: where the inside's steps are the
#: smaller, as in an H.264 clip's flat dark, up to the whole excess).
MAX_SHARE = 2.0
#: Pixels of the sampled frames the quantile maps are measured on (every few frames where there are more).
TABLE_PIXELS = 8 << 20
#: Quantiles of the map between the boundaries' excess steps and the inside's.
QUANTILES = np.concatenate([np.linspace(0.0, 0.99, 100), np.linspace(0.991, 1.0, 10)])
#: The plane-axis pairs, as ``Grid`` keys.
KEYS = ("luma16_x", "luma16_y", "luma_x", "luma_y", "chroma_x", "chroma_y")
#: Quantile maps per class of activity: the classes' edges, the boundaries' excess steps' quantiles
#: per class, the inside's, the share of the maps' removal taken away.
Table = tuple[np.ndarray, np.ndarray, np.ndarray, float]


@dataclass(frozen=True)
class Grid:
    """A clip's block grid: per plane and axis (:data:`KEYS`) whether one was found, the
    boundaries' step ratio, and the quantile map of their excess steps (``(boundary, inside)``
    quantiles of its magnitude)."""

    found: dict[str, bool]
    ratios: dict[str, float]
    maps: dict[str, Table] = field(repr=False)

    @property
    def any(self) -> bool:
        return any(self.found.values())

    def describe(self) -> str:
        """The grid in a few words, e.g. ``luma 8 px x+y (1.72/1.22), chroma 16 px x+y (4.03/3.65)``."""
        parts = []
        for plane, side in (("luma16", 2 * PERIOD), ("luma", PERIOD), ("chroma", 2 * PERIOD)):
            axes = [a for a in "xy" if self.found[f"{plane}_{a}"]]
            if axes:
                ratios = "/".join(f"{min(self.ratios[f'{plane}_{a}'], MAX_SHOWN):.2f}" for a in axes)
                parts.append(f"{plane} {side} px {'+'.join(axes)} ({ratios})")
        return ", ".join(parts) or "none"


def planes(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Luma ``(T, H, W)`` and chroma at half resolution ``(T, H // 2, W // 2, 2)`` (B - Y and
    R - Y averaged over 2 x 2 pixels) of ``frames`` ``(T, H, W, C)`` (uint8, or float32 levels or
    tone values), float32; grey frames have no chroma."""
    f = frames if frames.dtype == np.float32 else frames.astype(np.float32)
    if f.shape[-1] == 1:
        return f[..., 0], None
    y = LUMA[0] * f[..., 0] + LUMA[1] * f[..., 1] + LUMA[2] * f[..., 2]
    t, h, w = y.shape
    c = np.empty((t, h // 2, w // 2, 2), np.float32)
    for k, ch in enumerate((2, 0)):
        diff = f[:, : h - h % 2, : w - w % 2, ch] - y[:, : h - h % 2, : w - w % 2]
        c[..., k] = diff.reshape(t, h // 2, 2, w // 2, 2).mean(axis=(2, 4))
    return y, c


def _last(plane: np.ndarray, axis: int) -> np.ndarray:
    """``plane`` with ``axis`` moved last (a view)."""
    return np.moveaxis(plane, axis, -1)


def step_profile(plane: np.ndarray, axis: int) -> np.ndarray:
    """Mean absolute step between neighbours along ``axis`` of ``plane``, one value per pair."""
    d = np.abs(np.diff(_last(plane, axis), axis=-1))
    return d.reshape(-1, d.shape[-1]).mean(axis=0, dtype=np.float64)


def phase_ratios(profile: np.ndarray, period: int = PERIOD) -> np.ndarray:
    """Per phase of ``period``: the median over its pairs of the step there over the median of
    the :data:`SIDE` steps each side (pairs without a full side left out; 1.0 where none)."""
    n = len(profile)
    out = np.ones(period)
    tiny = 1e-9 + 1e-6 * float(profile.mean())
    for phase in range(period):
        b = np.arange(phase, n, period)
        b = b[(b >= SIDE) & (b + SIDE < n)]
        if len(b):
            beside = np.stack([profile[b + k] for k in range(-SIDE, SIDE + 1) if k])
            out[phase] = float(np.exp(np.median(np.log((profile[b] + tiny) / (np.median(beside, axis=0) + tiny)))))
    return out


def _steps(plane: np.ndarray, phase: int, period: int) -> list[np.ndarray]:
    """The steps ``s(-2) .. s(2)`` along ``plane``'s last axis around the pairs ``(phase + k *
    period, phase + k * period + 1)`` (``s(0)`` theirs), for as many ``k`` as the boundaries
    (``period - 1``) have two pixels on either side; ``phase`` >= 2."""
    count = len(range(period - 1, plane.shape[-1] - 3, period))
    cols = [plane[..., phase + k :: period][..., :count] for k in range(-2, 4)]
    return [b - a for a, b in zip(cols, cols[1:])]


def excess_activity(plane: np.ndarray, phase: int, period: int = PERIOD) -> tuple[np.ndarray, np.ndarray]:
    """At the pairs of ``phase`` (:func:`_steps`): the excess step ``s(0) - (s(-1) + s(1)) / 2``
    and the activity beside it, the mean of ``|s(-2)|, |s(-1)|, |s(1)|, |s(2)|``."""
    s = _steps(plane, phase, period)
    return s[2] - (s[1] + s[3]) / 2, (np.abs(s[0]) + np.abs(s[1]) + np.abs(s[3]) + np.abs(s[4])) / 4


def _passes(plane_name: str) -> list[tuple[str, int, int]]:
    """The smoothing passes of a plane in their order: key, axis of ``(T, H, W[, 2])``, period."""
    out = [(f"{plane_name}16_{a}", ax, 2 * PERIOD) for a, ax in (("x", 2), ("y", 1))] if plane_name == "luma" else []
    return out + [(f"{plane_name}_{a}", ax, PERIOD) for a, ax in (("x", 2), ("y", 1))]


def sample(frames: np.ndarray) -> np.ndarray:
    """The indices of the up to :data:`SAMPLE_FRAMES` frames, evenly spread, a detection looks at."""
    return even_sample(frames.shape[0], SAMPLE_FRAMES)


def detect_grid(frames: np.ndarray, *, every: bool = False, found: dict[str, bool] | None = None) -> Grid:
    """The block grid of ``frames`` ``(T, H, W, C)`` uint8 (or float32) (:class:`Grid`), measured
    on up to :data:`SAMPLE_FRAMES` of them; each pass's quantile maps are measured on the frames as
    the passes before it (those of a found grid, or all with ``every``) leave them. With ``found``
    (a grid's :attr:`Grid.found`), those passes are the grid's, whatever these frames' ratios.

    >>> rng = np.random.default_rng(0)
    >>> noise = rng.integers(0, 256, (8, 64, 64, 3)).astype(np.uint8)
    >>> detect_grid(noise).any
    False
    >>> blocks = np.repeat(np.repeat(rng.integers(0, 256, (8, 8, 8, 3)), 8, 1), 8, 2).astype(np.uint8)
    >>> detect_grid(blocks).describe().split(" (")[0]
    'luma 8 px x+y'
    """
    pick = sample(frames)
    luma, chroma = planes(frames[pick])
    # the quantile maps from every few of those frames, at most TABLE_PIXELS of them
    sub = slice(None, None, -(-len(pick) * frames[0, ..., 0].size // TABLE_PIXELS))
    given, found, ratios, maps = found, {}, {}, {}
    identity = (np.array([-np.inf, np.inf]), np.zeros((1, len(QUANTILES))), np.zeros((1, len(QUANTILES))), 0.0)
    for plane_name, values in (("luma", luma), ("chroma", chroma)):
        current = None if values is None else values[sub]
        for key, axis, period in _passes(plane_name):
            found[key], ratios[key], maps[key] = False, 1.0, identity
            if values is None or values.shape[axis] < 2 * period + 2:
                continue
            r = phase_ratios(step_profile(values, axis), period)
            ratios[key] = float(r[period - 1])
            found[key] = bool(r[-1] >= MIN_RATIO and r[-1] >= MARGIN * r[:-1].max()) if given is None else given[key]
            maps[key] = _table(np.ascontiguousarray(_last(current, axis)), period)
            if found[key] or every:
                current = current + np.moveaxis(_smoothing(_last(current, axis), maps[key], period), -1, axis)
    return Grid(found, ratios, maps)


def _removal(e: np.ndarray, activity: np.ndarray, table: Table) -> np.ndarray:
    """What the quantile maps ``table`` remove of the excess steps ``e`` at pairs of ``activity``."""
    edges, boundary, inside, share = table
    mag = np.abs(e)
    which = np.clip(np.searchsorted(edges, activity, side="right") - 1, 0, len(boundary) - 1)
    # one interpolation through the classes' maps laid end to end, each class offset past the last
    offset = 2.0 * float(boundary.max()) + 1.0
    shift = offset * np.arange(len(boundary))
    kept = np.interp(
        np.minimum(mag, boundary[which, -1]) + shift[which], (boundary + shift[:, None]).ravel(), inside.ravel()
    )
    # past the sample's largest step, the largest removal
    over = mag - (boundary[which, -1] - inside[which, -1])
    kept = np.where(mag > boundary[which, -1], over, kept)
    return np.sign(e) * np.minimum(share * (mag - np.minimum(kept, mag)), mag)


def _table(plane: np.ndarray, period: int) -> Table:
    """The quantile maps of the excess steps of ``plane`` (its last axis the one smoothed) at the
    boundaries of ``period``: per class of activity (:data:`CLASSES`, equally many boundaries
    each) the boundaries' and the inside's quantiles, and the share of the maps' removal that
    brings the boundaries' mean absolute step to the inside's (the maps alone overshoot on a fine
    texture)."""
    e, act = excess_activity(plane, period - 1, period)
    edges = np.quantile(act, np.linspace(0.0, 1.0, CLASSES + 1))
    edges[0], edges[-1] = -np.inf, np.inf
    inside = [excess_activity(plane, p, period) for p in range(2, period) if p % PERIOD in INSIDE]
    e_in = np.concatenate([x.ravel() for x, _ in inside])
    act_in = np.concatenate([a.ravel() for _, a in inside])
    qb, qi = np.zeros((CLASSES, len(QUANTILES))), np.zeros((CLASSES, len(QUANTILES)))
    for k in range(CLASSES):
        sel_b = (act >= edges[k]) & (act < edges[k + 1])
        sel_i = (act_in >= edges[k]) & (act_in < edges[k + 1])
        if sel_b.any() and sel_i.any():
            qb[k] = np.quantile(np.abs(e[sel_b]), QUANTILES)
            qi[k] = np.quantile(np.abs(e_in[sel_i]), QUANTILES)
        else:
            qb[k] = qi[k] = np.quantile(np.abs(e), QUANTILES)
    # the inside's pairs: neither a boundary of the grid nor of an H.264 4 x 4 transform
    target = np.mean([np.abs(_steps(plane, p, period)[2]).mean() for p in range(2, period) if p % 4 != 3])
    delta = _steps(plane, period - 1, period)[2]
    removed = _removal(e, act, (edges, qb, qi, 1.0)) * (1 - 1 / period)
    shares = np.linspace(0.0, MAX_SHARE, 41)
    gaps = [abs(float(np.abs(delta - a * removed).mean()) - target) for a in shares]
    return edges, qb, qi, float(shares[int(np.argmin(gaps))])


def _smoothing(plane: np.ndarray, table: Table, period: int) -> np.ndarray:
    """The correction of ``plane`` (float32, its last axis the one smoothed) that removes
    :func:`_removal` of its excess steps at the boundaries of ``period`` as ramps over half a
    period each side."""
    corr = np.zeros(plane.shape, np.float32)
    e, act = excess_activity(plane, period - 1, period)
    if not e.shape[-1]:
        return corr
    removed = _removal(e, act, table).astype(np.float32)
    half = period // 2
    ramp = ((np.arange(-half, half) + half + 0.5) / period - (np.arange(-half, half) >= 0)).astype(np.float32)
    # boundary k's ramp covers the pixels half + k * period .. half + (k + 1) * period - 1
    n, count = plane.shape[-1], removed.shape[-1]
    whole = min(count, (n - half) // period)
    windows = corr[..., half : half + whole * period].reshape(*corr.shape[:-1], whole, period)
    windows += removed[..., :whole, None] * ramp
    for k in range(whole, count):
        width = n - (half + k * period)
        corr[..., half + k * period :] += removed[..., k, None] * ramp[:width]
    return corr


def deblock(frames: np.ndarray, grid: Grid, *, every: bool = False) -> np.ndarray:
    """``frames`` ``(T, H, W, C)`` with the excess steps at ``grid``'s boundaries mapped to the
    inside's (where a grid was found, or on every plane and axis with ``every``), float32 on the
    frames' scale (levels: a value may leave 0..255 by a fraction of a level; or tone values);
    the frames as they are where nothing is smoothed."""
    out = frames.astype(np.float32)
    keys = [k for k in KEYS if every or grid.found[k]]
    if not keys:
        return out
    for lo in range(0, len(frames), CHUNK):
        f = out[lo : lo + CHUNK]
        luma, chroma = planes(f)
        d_luma = _plane_correction(luma, grid, "luma", keys)
        if d_luma is not None:
            f += d_luma[..., None]
        d_chroma = None if chroma is None else _plane_correction(chroma, grid, "chroma", keys)
        if d_chroma is None:
            continue
        t, h2, w2 = d_chroma.shape[:3]
        cells = f[:, : 2 * h2, : 2 * w2].reshape(t, h2, 2, w2, 2, 3)
        d_cb, d_cr = d_chroma[:, :, None, :, None, 0], d_chroma[:, :, None, :, None, 1]
        cells[..., 0] += d_cr
        cells[..., 1] -= (LUMA[0] * d_cr + LUMA[2] * d_cb) / LUMA[1]
        cells[..., 2] += d_cb
    return out


def _plane_correction(plane: np.ndarray, grid: Grid, name: str, keys: list[str]) -> np.ndarray | None:
    """The correction of ``plane`` (``(T, H, W[, 2])``) by its passes among ``keys`` (each
    measured on the plane as the one before left it), or None where it has none."""
    corr = None
    for key, axis, period in _passes(name):
        if key not in keys:
            continue
        current = plane if corr is None else plane + corr
        d = np.moveaxis(_smoothing(_last(current, axis), grid.maps[key], period), -1, axis)
        corr = d if corr is None else corr + d
    return corr


def choose(frames: np.ndarray | None, mode: str) -> tuple[Grid | None, dict]:
    """The grid to smooth away for the ``deblock`` parameter ``mode`` ("auto": where one is
    found, "on": every plane and axis, "off": none) and the facts a model's info records:
    ``codec_grid`` (what :meth:`Grid.describe` says of the grid found, with "on" too; "not
    measured" when off) and ``deblocked``.
    ``frames`` None (a streamed clip): nothing smoothed, and "on" is refused."""
    if frames is None:
        if mode == "on":
            raise InvalidArgumentError("deblock='on' needs the clip in memory; a streamed clip is learned as it is")
        return None, {"codec_grid": "not measured (streamed clip)", "deblocked": False}
    if mode == "off":
        return None, {"codec_grid": "not measured", "deblocked": False}
    grid = detect_grid(frames, every=mode == "on")
    smooth = mode == "on" or grid.any
    info = {"codec_grid": grid.describe(), "deblocked": bool(smooth)}  # what was found, even where forced
    if mode == "on":
        grid = Grid(dict.fromkeys(KEYS, True), grid.ratios, grid.maps)
    return (grid if smooth else None), info


def in_tone(frames: np.ndarray, grid: Grid, tone: ToneModel) -> list[Grid]:
    """Per channel of ``frames`` ``(T, H, W, C)`` uint8, the grid (:class:`Grid`, found in levels)
    to smooth away in its tone values (:func:`~dynatex.analyzer.tone.to_tone`), each channel a
    plane of its own with quantile maps measured there. The map is steep where a channel's values
    pile up, so the luma's grid shows in each channel by its own amount and would leave the
    chroma's difference planes with an 8-px grid: each channel takes the luma's passes, and those
    of the chroma's grid where it was found."""
    picked = frames[sample(frames)]
    values = to_tone(picked, tone).reshape(picked.shape)
    found = dict.fromkeys(KEYS, False)
    for a in "xy":
        found[f"luma16_{a}"] = grid.found[f"luma16_{a}"] or grid.found[f"chroma_{a}"]
        found[f"luma_{a}"] = grid.found[f"luma_{a}"] or grid.found[f"chroma_{a}"]
    return [
        Grid(found, grid.ratios, detect_grid(values[..., ch : ch + 1], found=found).maps)
        for ch in range(values.shape[-1])
    ]


def learning_values(frames: np.ndarray, grid: Grid | None, tone: ToneModel | None) -> tuple[np.ndarray, np.ndarray]:
    """What a projection model learns from: ``frames`` ``(T, H, W, C)`` uint8 smoothed by ``grid``
    (:func:`deblock`; in levels held to 0..255, or with ``tone`` in its tone values,
    :func:`in_tone`, held to the map's range), float32 ``(T, H * W * C)``; and the smoothed frames as levels rounded to
    uint8 (smoothed in levels: rounding a ramp in tone values back to levels puts its level step
    back on the boundary), which the detail part measures the model's residual against. Where ``grid`` is None:
    the frames' values (:func:`~dynatex.analyzer.tone.to_tone` with a map) and the frames themselves."""
    t = frames.shape[0]
    if grid is None:
        return (frames.reshape(t, -1).astype(np.float32) if tone is None else to_tone(frames, tone)), frames
    out = np.empty((t, frames[0].size), np.float32)
    rounded = np.empty_like(frames)
    toned = None if tone is None else in_tone(frames, grid, tone)
    for lo in range(0, t, CHUNK):
        block = frames[lo : lo + CHUNK]
        chunk = np.clip(deblock(block, grid), 0.0, 255.0)
        np.rint(chunk, out=rounded[lo : lo + CHUNK], casting="unsafe")
        if toned is not None:
            chunk = to_tone(block, tone).reshape(block.shape)
            for ch, g in enumerate(toned):
                ramp = deblock(chunk[..., ch : ch + 1], g)
                chunk[..., ch : ch + 1] = np.clip(ramp, tone.forward[ch, 0], tone.forward[ch, -1])
        out[lo : lo + CHUNK] = chunk.reshape(len(chunk), -1)
    return out, rounded
