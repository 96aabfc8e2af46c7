"""Learning the fine detail a projection model drops, and the source's per-pixel colour range.

The ``lds`` and ``mixture`` models keep a clip's top components; what they leave out (the
truncation residual: fine, fast detail, a quarter of the variance of a sea) is what makes
their output look blurred and slow. It is modelled here as a stationary Gaussian texture:

1. the residual's principal colour axis (a 3 x 3 eigendecomposition): 93% to 99.6% of its
   variance on noise-like clips (sea, steam, fire); the other axes are left out, because on a
   clip with structured colour (a flag's edges, 11% there) their noise is red and green confetti;
2. its local level, a per-pixel gain (the residual's RMS, smoothed), which the stationary
   texture is multiplied by;
3. along that axis, its spatio-temporal power spectrum (Welch: cuboids of ``Tv`` frames by
   ``Hv x Wv`` pixels, half overlapping, Hann-windowed), which holds its motion: detail that
   flows along the clip's motion puts its power on the planes of those velocities. The residual
   is not divided by its level first: where the level is near zero (a still background) that
   division amplifies rounding into white noise, which whitens the whole spectrum (seen as
   whole-region flicker);
4. a noise volume drawn with that spectrum and random phases, periodic in t, y and x by
   construction, along the axis in RGB, stored as int8, its variance (times the gain's) the
   whole residual's energy: the detail brings back the variance the projection drops.

The player (:mod:`dynatex.player.engines.detail`) plays the volume through two layers at random
offsets cross-faded with weights whose squares sum to one, scales it by the gain and holds
every pixel to the colour range the source showed there (``low``/``high``: the per-pixel,
per-channel minimum and maximum over the clip, widened to the 3 x 3 neighbourhood); a pixel
whose detail would give it a colour the clip never had (``colours``, the set
:func:`~dynatex.analyzer.metrics.out_of_gamut_share` measures against) gets none.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..checks import check_seed
from ..tiledb.detail import MAX_GAIN, DetailModel
from .metrics import colour_set

#: Frames, rows and columns of the noise volume (capped by the clip's own).
VOLUME_FRAMES = 32
VOLUME_SIDE = 128
#: Side of the box that smooths the per-pixel gain.
GAIN_BOX = 9
#: The int8 volume spans this many standard deviations of its largest channel.
CLIP_SIGMAS = 5.0
#: Frames of residual computed at once.
CHUNK = 16
#: A residual with more of its power than this at wavelengths over a quarter of the noise
#: volume's side is structure, not fine detail: played over a frame larger than the volume its
#: blobs repeat across the frame (a flame clip's leopard spots), so such a model gets no detail.
COARSE_SHARE = 0.5

Reconstruct = Callable[[int, int], np.ndarray]


def volume_shape(t: int, h: int, w: int) -> tuple[int, int, int]:
    """Frames, rows and columns of the noise volume of a ``t``-frame clip of ``h x w`` pixels."""
    tv = min(VOLUME_FRAMES, max(2, t // 2))
    return tv - tv % 2, min(VOLUME_SIDE, h), min(VOLUME_SIDE, w)  # even: the layers are half a volume apart


def workspace_bytes(shape: tuple[int, ...]) -> int:
    """Bytes :func:`learn_detail` needs beyond the clip and the model, for frames ``(T, H, W, C)``:
    the volume's FFTs (at most 32 x 128 x 128 values, so bounded), one volume of the levelled
    residual and a few chunks of residual frames."""
    t, h, w, c = shape
    tv, hv, wv = volume_shape(t, h, w)
    return 48 * tv * hv * wv + 4 * tv * h * w + 3 * 4 * CHUNK * h * w * c


def learn_detail(frames: np.ndarray, reconstruct: Reconstruct, *, seed: int = 0) -> DetailModel:
    """The detail part of a projection model of ``frames`` ``(T, H, W, C)`` uint8.

    ``reconstruct(t0, t1)`` returns the model's own frames ``t0:t1`` as float32 ``(t1 - t0, H*W*C)``
    (mean included); the residual is the clip minus them. ``seed`` draws the volume's phases.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clip = rng.integers(0, 256, (20, 16, 16, 3)).astype(np.uint8)
    >>> mean = clip.reshape(20, -1).mean(axis=0, dtype=np.float32)
    >>> d = learn_detail(clip, lambda a, b: np.broadcast_to(mean, (b - a, mean.size)))
    >>> d.volume.shape, d.volume.dtype.name, bool((d.low <= d.high).all())
    ((10, 16, 16, 3), 'int8', True)
    """
    seed = check_seed("seed", seed)
    t, h, w, c = frames.shape
    tv, hv, wv = volume_shape(t, h, w)

    # Pass 1: colour covariance, per-pixel energy and colour range.
    cov = np.zeros((c, c))
    energy = np.zeros((h, w))
    low = frames.min(axis=0)
    high = frames.max(axis=0)
    total = 0.0
    for _, r in _residual_chunks(frames, reconstruct):
        flat = r.reshape(-1, c)
        cov += flat.T @ flat
        energy += np.einsum("thwc,thwc->hw", r, r, dtype=np.float64)
    clip_mean = frames.reshape(t, -1).mean(axis=0, dtype=np.float64).astype(np.float32)
    for t0 in range(0, t, CHUNK):
        d = frames[t0 : t0 + CHUNK].reshape(-1, clip_mean.size).astype(np.float32)
        d -= clip_mean
        total += float(np.einsum("ij,ij->", d, d, dtype=np.float64))
    resid_energy = float(np.trace(cov))
    eig, axes = np.linalg.eigh(cov)
    axis = axes[:, -1]
    # a box filter by running sums leaves rounding-sized negatives where the energy is ~0
    level = np.sqrt(np.maximum(_box(energy / (t * c), GAIN_BOX), 0.0))
    rms = np.sqrt(np.mean(level**2))
    norm_gain = level / rms if rms > 0 else np.ones_like(level)

    # Pass 2: the spatio-temporal power spectrum of the residual along its principal colour axis.
    window = (_hann(tv)[:, None, None] * _hann(hv)[None, :, None] * _hann(wv)[None, None, :]).astype(np.float32)
    power = np.zeros((tv, hv, wv // 2 + 1))
    segments = 0
    starts_t = _starts(t, tv)
    a = np.empty((tv, h, w), np.float32)
    axis32 = axis.astype(np.float32)
    for t0 in starts_t:
        for k, r in _residual_chunks(frames[t0 : t0 + tv], reconstruct, offset=t0):
            np.matmul(r, axis32, out=a[k : k + len(r)])
        for y0 in _starts(h, hv):
            for x0 in _starts(w, wv):
                cube = a[:, y0 : y0 + hv, x0 : x0 + wv]
                power += np.abs(np.fft.rfftn((cube - cube.mean()) * window)) ** 2
                segments += 1
    # The whole residual's energy, its other colour axes' included.
    var = resid_energy / (t * h * w) / max(float(np.mean(norm_gain**2)), 1e-12)

    # The volume: random phases under that amplitude, scaled to the variance, along the axis in RGB.
    rng = np.random.default_rng(seed)
    white = np.fft.rfftn(rng.standard_normal((tv, hv, wv)))
    field = np.fft.irfftn(white * np.sqrt(power / max(segments, 1)), s=(tv, hv, wv), axes=(0, 1, 2))
    sd = field.std()
    field *= np.sqrt(var) / sd if sd > 0 else 0.0
    span = CLIP_SIGMAS * np.sqrt(var) * float(np.abs(axis).max())
    scale = span / 127.0 if span > 0 else 1.0
    volume = np.empty((tv, hv, wv, c), np.int8)
    for ch in range(c):  # channel by channel: temporaries of one channel's size
        volume[..., ch] = np.clip(np.rint(field * (axis[ch] / scale)), -127, 127)
    gain = np.clip(norm_gain * scale, 0, MAX_GAIN).astype(np.float32)
    info = {
        "residual_energy": resid_energy / total if total > 0 else 0.0,
        "coarse_share": coarse_share(power),
        "volume_scale": float(scale),
        "colour_share": float(eig[-1] / eig.sum()) if eig.sum() > 0 else 1.0,
        "seed": int(seed),
    }
    low, high = _dilate(low, np.minimum), _dilate(high, np.maximum)
    colours = colour_set(frames).astype(np.uint8)
    return DetailModel(volume=volume, gain=gain, low=low, high=high, colours=colours, info=info)


def coarse_share(power: np.ndarray) -> float:
    """Share of ``power`` (a ``(Tv, Hv, Wv // 2 + 1)`` real-FFT power spectrum) at spatial
    wavelengths over a quarter of the volume's shorter side.

    >>> p = np.zeros((2, 16, 9)); p[:, 1, 0] = 1.0; p[:, 0, 8] = 3.0  # 16 px across, 2 px along rows
    >>> coarse_share(p)
    0.25
    """
    _, hv, half = power.shape
    wv = 2 * (half - 1)
    k = np.hypot(np.fft.fftfreq(hv)[:, None], np.fft.rfftfreq(wv)[None, :])
    weight = np.full(half, 2.0)  # a real FFT's inner columns stand for two frequencies
    weight[0] = 1.0
    weight[-1] = 1.0
    p = power.sum(axis=0) * weight[None, :]
    total = float(p.sum())
    return float(p[k < 4.0 / min(hv, wv)].sum() / total) if total > 0 else 0.0


def attach_detail(model, frames: np.ndarray, reconstruct: Reconstruct, *, seed: int = 0) -> None:
    """Set ``model.detail`` (an lds or mixture model) to :func:`learn_detail` of ``frames``, unless
    the residual is coarse (:data:`COARSE_SHARE`) and the frame larger than the noise volume: then
    leave it None and record the share as ``model.info["detail_coarse_share"]``, which
    :func:`~dynatex.tiledb.detail.describe` turns into a warning."""
    detail = learn_detail(frames, reconstruct, seed=seed)
    _, h, w, _ = frames.shape
    _, hv, wv, _ = detail.volume.shape
    share = float(detail.info["coarse_share"])
    if share > COARSE_SHARE and (h > hv or w > wv):
        model.info["detail_coarse_share"] = share
        return
    model.detail = detail


def _residual_chunks(frames: np.ndarray, reconstruct: Reconstruct, offset: int = 0):
    """``(t0, residual)`` of ``frames``, CHUNK frames at a time, float32 ``(t, H, W, C)``."""
    shape = frames.shape[1:]
    for t0 in range(0, frames.shape[0], CHUNK):
        block = frames[t0 : t0 + CHUNK]
        r = block.reshape(len(block), -1).astype(np.float32)
        r -= reconstruct(offset + t0, offset + t0 + len(block))
        yield t0, r.reshape((len(block),) + shape)


def _starts(size: int, span: int) -> list[int]:
    """Starts of windows of ``span`` over ``size``, half overlapping, the last one flush with the end."""
    if span >= size:
        return [0]
    starts = list(range(0, size - span + 1, max(1, span // 2)))
    if starts[-1] != size - span:
        starts.append(size - span)
    return starts


def _hann(n: int) -> np.ndarray:
    return np.hanning(n + 2)[1:-1] if n > 1 else np.ones(1)


def _box(a: np.ndarray, size: int) -> np.ndarray:
    """Mean over a ``size x size`` box (edge-replicated)."""
    r = size // 2
    p = np.pad(a, r, mode="edge")
    c = np.cumsum(np.cumsum(p, axis=0), axis=1)
    c = np.pad(c, ((1, 0), (1, 0)))
    h, w = a.shape
    s = c[size : size + h, size : size + w] - c[:h, size : size + w] - c[size : size + h, :w] + c[:h, :w]
    return s / (size * size)


def _dilate(a: np.ndarray, op) -> np.ndarray:
    """``op`` (np.minimum or np.maximum) over each pixel's 3 x 3 neighbourhood, per channel."""
    p = np.pad(a, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = a.shape[:2]
    out = a.copy()
    for dy in range(3):
        for dx in range(3):
            out = op(out, p[dy : dy + h, dx : dx + w])
    return out
