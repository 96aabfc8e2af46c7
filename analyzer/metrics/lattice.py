"""Repetition in space: a cell lattice standing out of the output."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...checks import check_frames, check_int
from ...errors import InvalidArgumentError
from ...framestats import float_chunks
from ._common import int_pair, luma


def lattice_correlation(frames: np.ndarray, period: int | Sequence[int]) -> tuple[float, float]:
    """Spatial repetition at a lattice period: ``(along y, along x)`` correlation of each frame
    with itself shifted by ``period`` ``(py, px)``, averaged over frames.

    The luma of each frame, minus its mean, is correlated (Pearson) with the same frame
    moved by ``py`` rows, and by ``px`` columns. A natural texture is near 0 at any lag
    longer than its own structures; content that repeats at every tile of a lattice raises
    it (a lattice of one tile: 1). Compare with the source at the same lags.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> tile = rng.integers(0, 256, (1, 8, 8)).astype(np.uint8)
    >>> tiled = np.tile(tile, (1, 4, 4))
    >>> [round(v, 3) for v in lattice_correlation(tiled, 8)]
    [1.0, 1.0]
    >>> noise = rng.integers(0, 256, (2, 32, 32)).astype(np.uint8)
    >>> bool(max(lattice_correlation(noise, 8)) < 0.1)
    True
    """
    frames = check_frames(frames)
    py, px = int_pair("period", period, 1)
    t, h, w = frames.shape[:3]
    if py >= h or px >= w:
        raise InvalidArgumentError(f"period {py}x{px} must be smaller than the {h}x{w} frame")
    acc = np.zeros(2)
    for _, chunk in float_chunks(frames):
        for g in luma(chunk):
            g = g - g.mean()
            for k, (a, b) in enumerate(((g[:-py], g[py:]), (g[:, :-px], g[:, px:]))):
                den = np.sqrt(float((a * a).mean()) * float((b * b).mean()))
                acc[k] += float((a * b).mean()) / den if den > 0 else 0.0
    return float(acc[0] / t), float(acc[1] / t)


def lattice_lags(tile: int | Sequence[int]) -> list[tuple[int, int]]:
    """The lags of a ``(th, tw)`` cell lattice at which :func:`lattice_prominence` looks:
    ``(0, tw), (th, 0), (th, tw), (0, 2 tw), (2 th, 0)``."""
    th, tw = int_pair("tile", tile, 1)
    return [(0, tw), (th, 0), (th, tw), (0, 2 * tw), (2 * th, 0)]


def _autocorrelation(g: np.ndarray, max_dy: int, max_dx: int) -> np.ndarray:
    """Normalised autocorrelation of one mean-removed luma frame ``g (H, W)`` at lags
    ``dy in [0, max_dy]``, ``dx in [-max_dx, max_dx]``: ``(max_dy + 1, 2 max_dx + 1)``, the mean
    product over each lag's overlap divided by the frame's variance (zero-padded FFT, so no
    wrap-around)."""
    h, w = g.shape
    fh, fw = 2 * h, 2 * w
    spec = np.fft.rfft2(g, (fh, fw))
    ac = np.fft.irfft2(spec * np.conj(spec), (fh, fw))
    dys = np.arange(max_dy + 1)
    dxs = np.arange(-max_dx, max_dx + 1)
    raw = ac[dys[:, None], dxs[None, :] % fw]
    count = (h - dys)[:, None] * (w - np.abs(dxs))[None, :]
    var = float((g * g).mean())
    return raw / count / var if var > 0 else np.zeros_like(raw)


def lattice_prominence(
    frames: np.ndarray, tile: int | Sequence[int], *, max_frames: int = 30, per_lag: bool = False
) -> float | None | tuple[float | None, dict]:
    """How much a cell lattice ``(th, tw)`` stands out in the output's autocorrelation.

    For each frame (at most ``max_frames``, evenly spread), the normalised autocorrelation of
    its mean-removed luma at each lattice lag (:func:`lattice_lags`) minus the mean of the
    autocorrelation over a ring of lags ``3 <= |d - lag| <= max(6, min(th, tw) / 4)`` around
    it; the median over lags and frames. Content repeated at every cell makes a peak at the
    lattice lags that its surroundings do not share (a wallpaper of one tile: about 1); a
    natural texture, or a smooth correlation that merely decays with distance, gives about 0.
    Lags whose ring does not fit inside the frame with at least a quarter of the frame
    overlapping (in each direction) are left out; None when none fits.

    With ``per_lag`` returns ``(prominence, {"(dy, dx)": median over frames})``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> tile = rng.integers(0, 256, (1, 16, 16)).astype(np.uint8)
    >>> round(lattice_prominence(np.tile(tile, (1, 6, 6)), 16), 2)
    1.0
    >>> noise = rng.integers(0, 256, (2, 96, 96)).astype(np.uint8)
    >>> abs(lattice_prominence(noise, 16)) < 0.02
    True
    """
    frames = check_frames(frames)
    th, tw = int_pair("tile", tile, 1)
    max_frames = check_int("max_frames", max_frames, 1)
    t, h, w = frames.shape[:3]
    r = max(6.0, min(th, tw) / 4.0)
    ri = int(np.ceil(r))
    lags = [(dy, dx) for dy, dx in lattice_lags((th, tw)) if dy + ri <= h - h // 4 and dx + ri <= w - w // 4]
    if not lags:
        return (None, {}) if per_lag else None
    max_dy = max(dy for dy, _ in lags) + ri
    max_dx = max(dx for _, dx in lags) + ri
    oy, ox = np.mgrid[-ri : ri + 1, -ri : ri + 1]
    dist = np.sqrt(oy * oy + ox * ox)
    ring = (dist >= 3) & (dist <= r)
    ry, rx = oy[ring], ox[ring]
    idx = np.unique(np.linspace(0, t - 1, min(max_frames, t)).round().astype(int))
    values = np.empty((len(idx), len(lags)))
    for fi, k in enumerate(idx):
        g = luma.__wrapped__(frames[k : k + 1])[0].astype(np.float64)  # one frame: not worth holding
        g -= g.mean()
        ac = _autocorrelation(g, max_dy, max_dx)
        for li, (dy, dx) in enumerate(lags):
            # the autocorrelation is symmetric: a lag of negative dy is the mirrored lag
            yy, xx = dy + ry, dx + rx
            xx = np.where(yy < 0, -xx, xx)
            yy = np.abs(yy)
            values[fi, li] = ac[dy, dx + max_dx] - ac[yy, xx + max_dx].mean()
    prom = float(np.median(values))
    if per_lag:
        return prom, {f"({dy}, {dx})": float(np.median(values[:, li])) for li, (dy, dx) in enumerate(lags)}
    return prom
