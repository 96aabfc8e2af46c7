"""Statistics of a clip and of its tiles (step 8 of :mod:`dynatex.analyzer.tiles`): how alike
the parts of the frames are (stationarity), and each tile's colours for tone fitting.
"""

from __future__ import annotations

import numpy as np

from .loop import even_sample, grey

# -- 9. spatial stationarity ---------------------------------------------------------------------
_STAT_OFFSETS = np.array([16.0, 4.0, 1.0])  # grey levels added to each statistic's median


def stationarity(frames: np.ndarray, *, grid: int = 4, n_frames: int = 48) -> tuple[float, dict]:
    """How alike the parts of each frame are: ``(figure, details)``, figure in (0, 1].

    Each of up to ``n_frames`` frames is split into ``grid x grid`` windows; per window its
    mean luma, its luma contrast (standard deviation) and its activity (mean absolute change
    to the next frame). Per statistic and frame, the most unusual window's excess over the
    median window, relative to the median (plus 16, 4 and 1 grey levels, so flat statistics
    do not divide by zero): a texture has every window alike, a single object on a plain
    background has one window unlike the rest. The median over frames of the largest of the
    three excesses is ``spread``; the figure is ``1 / (1 + spread)``. Below
    :data:`~dynatex.tiledb.tiles.STATIONARITY_WARN` (spread above 1) the clip is not a texture all over, and tiles
    cut from it repeat or misplace its structures (grass 0.74, sea 0.65; a moving disc on a
    plain background 0.32; a pendulum clock 0.20).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> noise = rng.integers(0, 256, (6, 64, 64, 3)).astype(np.uint8)
    >>> stationarity(noise)[0] > 0.8
    True
    >>> from dynatex.tiledb.tiles import STATIONARITY_WARN
    >>> still = np.full((6, 64, 64, 3), 90, np.uint8); still[:, 5:15, 5:15] = 250
    >>> stationarity(still)[0] < STATIONARITY_WARN
    True
    """
    t, h, w = frames.shape[:3]
    idx = np.unique(np.linspace(0, max(0, t - 2), min(max(1, t - 1), n_frames)).round().astype(int))
    nxt = np.minimum(idx + 1, t - 1)
    g = grey(frames[idx])
    act = np.abs(grey(frames[nxt]) - g)
    ys = np.linspace(0, h, grid + 1).astype(int)
    xs = np.linspace(0, w, grid + 1).astype(int)
    stats = np.empty((grid * grid, 3, len(idx)))
    for i in range(grid):
        for j in range(grid):
            win = g[:, ys[i] : ys[i + 1], xs[j] : xs[j + 1]]
            k = i * grid + j
            stats[k, 0] = win.mean(axis=(1, 2))
            stats[k, 1] = win.std(axis=(1, 2))
            stats[k, 2] = act[:, ys[i] : ys[i + 1], xs[j] : xs[j + 1]].mean(axis=(1, 2))
    med = np.median(stats, axis=0)
    excess = np.abs(stats - med).max(axis=0) / (med + _STAT_OFFSETS[:, None])
    per_stat = np.median(excess, axis=1)
    spread = float(per_stat.max())
    names = ("brightness", "contrast", "activity")
    return 1.0 / (1.0 + spread), {
        "spread": spread,
        "worst": names[int(np.argmax(per_stat))],
        **{f"spread_{n}": float(v) for n, v in zip(names, per_stat)},
    }


FEATURE_CORRELATION = 0.5  # the autocorrelation at which :func:`feature_scale` ends a feature
_FEATURE_ANGLES = 16


def feature_scale(frames: np.ndarray, *, n_frames: int = 8, max_lag: int | None = None) -> float:
    """The extent, in pixels, of the clip's largest coherent features: the longest lag, over
    :data:`_FEATURE_ANGLES` directions, out to which the luma autocorrelation (mean over up to
    ``n_frames`` frames, each minus its mean) stays at or above :data:`FEATURE_CORRELATION`.

    Fine-grained textures (snow, spray) score 1-3 pixels; waterfalls, smoke and waves 10-40, a
    streaked texture its streaks' length. Lags stop at ``max_lag`` (default half the shorter
    side), so the figure is at most about that.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> noise = rng.integers(0, 256, (4, 64, 64, 3)).astype(np.uint8)
    >>> feature_scale(noise) <= 1.0
    True
    >>> s = np.sin(2 * np.pi * np.arange(64) / 64)
    >>> blobs = np.broadcast_to(128 + 100 * s[:, None] * s[None, :], (4, 64, 64)).astype(np.uint8)
    >>> 10 <= feature_scale(blobs[..., None]) <= 15     # blobs 32 px across
    True
    >>> round(feature_scale(np.broadcast_to(blobs[:, :, 16:17], (4, 64, 64))[..., None]))  # streaks: the limit
    32
    """
    t, h, w = frames.shape[:3]
    lag = max(1, min(h, w) // 2 if max_lag is None else int(max_lag))
    g = grey(frames[even_sample(t, min(t, n_frames))])
    g = g - g.mean(axis=(1, 2), keepdims=True)
    spec = np.fft.rfft2(g, (2 * h, 2 * w))
    acf = np.fft.irfft2((spec * spec.conj()).real.sum(axis=0), (2 * h, 2 * w))
    ones = np.fft.rfft2(np.ones((h, w)), (2 * h, 2 * w))
    counts = np.fft.irfft2((ones * ones.conj()).real, (2 * h, 2 * w))
    acf = acf / np.maximum(counts, 1.0)  # mean product over each lag's overlap
    if acf[0, 0] <= 0:
        return 0.0
    acf /= acf[0, 0]
    r = np.arange(1, lag + 1)
    best = 0.0
    for a in np.linspace(0.0, np.pi, _FEATURE_ANGLES, endpoint=False):
        dy, dx = np.rint(r * np.sin(a)).astype(int), np.rint(r * np.cos(a)).astype(int)
        below = np.flatnonzero(acf[dy % (2 * h), dx % (2 * w)] < FEATURE_CORRELATION)
        last = int(below[0]) if below.size else lag  # lags 1 .. last stay above
        if last:
            best = max(best, float(np.hypot(dy[last - 1], dx[last - 1])))
    return best


# -- 8. colour statistics --------------------------------------------------------------------------
def colour_stats(tile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean RGB (0..255) and mean HSV (hue in degrees by circular mean, S and V in 0..1) of a tile."""
    import cv2

    u = even_sample(tile.shape[0], 16)
    rgb = tile[u].reshape(-1, 1, 3)
    mean_rgb = rgb.reshape(-1, 3).mean(axis=0, dtype=np.float64)
    hsv = cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2HSV).reshape(-1, 3).astype(np.float64)
    ang = np.deg2rad(hsv[:, 0])
    hue = float(np.rad2deg(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())) % 360.0)
    return mean_rgb, np.array([hue, hsv[:, 1].mean(), hsv[:, 2].mean()])


def stationarity_info(frames: np.ndarray) -> dict:
    figure, details = stationarity(frames)
    return {"stationarity": figure, "stationarity_worst": details["worst"]}
