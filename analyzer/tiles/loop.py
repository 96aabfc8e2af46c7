"""One texture's loop (steps 1-4 of :mod:`dynatex.analyzer.tiles`): the tile size from the
spatial period, the temporal loop and its per-pixel transitions, the optical flow, and the
looped clip a construction cuts its tiles from (:class:`Texture`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ...errors import InvalidArgumentError
from ...framestats import LUMA, even_sample
from ..video import Progress

DEFAULT_MIN_TILE = 32
DEFAULT_MAX_TILE = 256


SAMPLE_FRAMES = 48  # loop frames summed in the cut errors (evenly spread)
PRE_FRAMES = 12  # loop frames used to rank candidate positions
STEP_PAIRS = 64  # frame pairs in the stored median frame step (its cost does not grow with the clip)


# -- 1. tile size ------------------------------------------------------------------------------
def grey(frames: np.ndarray) -> np.ndarray:
    f = frames.astype(np.float32)
    return f @ LUMA if f.shape[-1] == 3 else f[..., 0]


def tile_period(
    frames: np.ndarray, *, min_tile: int = DEFAULT_MIN_TILE, max_tile: int = DEFAULT_MAX_TILE, n_frames: int = 8
) -> tuple[tuple[int, int], tuple[float, float], float]:
    """Tile size from the dominant spatial periodicity.

    Returns ``((th, tw), (period_y, period_x), strength)``: ``strength`` is the peak of the
    mean power spectrum over its median (beyond ~30 the texture is periodic and the tile
    is the smallest multiple of the period that is at least ``min_tile``; otherwise the
    tile is a quarter of the shorter frame side). Both are clamped to
    ``[min_tile, min(max_tile, 2/3 of the frame side)]``.

    Examples
    --------
    >>> x = np.arange(128)
    >>> img = (128 + 100 * np.sin(2 * np.pi * x / 16))[None, :].repeat(96, 0)
    >>> f = np.repeat(img[:, :, None], 3, axis=2).astype(np.uint8)[None].repeat(2, 0)
    >>> size, period, strength = tile_period(f, min_tile=40)
    >>> size[1], round(period[1])
    (48, 16)
    """
    t, h, w = frames.shape[:3]
    idx = np.linspace(0, t - 1, min(n_frames, t)).round().astype(int)
    g = grey(frames[idx])
    g -= g.mean(axis=(1, 2), keepdims=True)
    win = np.hanning(h)[:, None] * np.hanning(w)[None, :]
    power = (np.abs(np.fft.fft2(g * win)) ** 2).mean(axis=0)
    fy = np.abs(np.fft.fftfreq(h))[:, None]
    fx = np.abs(np.fft.fftfreq(w))[None, :]
    # ignore periods longer than the largest tile (and DC)
    fmin = 1.0 / max(2, min(max_tile, max(h, w)))
    valid = np.maximum(fy, fx) >= fmin
    power = np.where(valid, power, 0.0)
    med = float(np.median(power[valid])) if valid.any() else 0.0
    k = int(np.argmax(power))
    ky, kx = divmod(k, w)
    strength = float(power.flat[k] / med) if med > 0 else 0.0
    py = 1.0 / fy[ky, 0] if fy[ky, 0] > 0 else float("inf")
    px = 1.0 / fx[0, kx] if fx[0, kx] > 0 else float("inf")
    default = max(min_tile, min(max_tile, (min(h, w) // 4) // 8 * 8))

    def size(period: float, side: int) -> int:
        hi = max(min_tile, min(max_tile, (2 * side) // 3))  # room for the overlap bands
        if strength >= 30 and np.isfinite(period) and period >= 2:
            m = int(np.ceil(min_tile / period))
            s = int(round(m * period))
            if s <= hi:
                return s
        return min(default, hi)

    return (size(py, h), size(px, w)), (float(py), float(px)), strength


# -- 2./3. temporal loop ---------------------------------------------------------------------
def _thumbs(frames: np.ndarray, side: int = 48) -> np.ndarray:
    t, h, w = frames.shape[:3]
    sy, sx = max(1, h // side), max(1, w // side)
    g = np.empty((t, h // sy, w // sx), np.float32)
    for i in range(0, t, 64):
        gg = grey(frames[i : i + 64, : (h // sy) * sy, : (w // sx) * sx])
        g[i : i + 64] = gg.reshape(gg.shape[0], h // sy, sy, w // sx, sx).mean(axis=(2, 4))
    return g.reshape(t, -1)


def find_loop(
    frames: np.ndarray,
    *,
    min_loop: int,
    max_loop: int | None = None,
    transition: int = 8,
    length: int | None = None,
    prefer_long: float = 0.5,
) -> tuple[int, int, float]:
    """``(start, length, cost)`` of the best loop.

    ``cost`` is the mean RMS thumbnail difference between the frame sets
    ``start + j`` and ``start + length + j`` (``j < transition``) over the median
    consecutive-frame difference. With ``length`` given only the start is searched.
    """
    t = frames.shape[0]
    o = transition
    if length is not None:
        if t < length + o:
            raise InvalidArgumentError(
                f"clip has {t} frames, fewer than the loop length {length} plus the transition {o}"
            )
        lengths = [length]
    else:
        if t < min_loop + o:
            raise InvalidArgumentError(
                f"clip has {t} frames, fewer than the shortest loop: min_loop={min_loop} plus transition={o} frames"
            )
        hi = t - o if max_loop is None else min(max_loop, t - o)
        lengths = list(range(min_loop, hi + 1))
    th = _thumbs(frames)
    sq = (th * th).sum(axis=1)
    d = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2 * th @ th.T, 0) / th.shape[1])
    med = float(np.median(np.diag(d, 1))) or 1e-3
    lmax = max(lengths)
    best = (np.inf, 0, lengths[0], np.inf)
    for ln in lengths:
        n_start = t - ln - o + 1
        diag = np.diag(d, ln)  # d[i, i + ln]
        c = np.lib.stride_tricks.sliding_window_view(diag[: n_start + o - 1], o).mean(axis=1)[:n_start] / med
        s = int(np.argmin(c))
        score = float(c[s]) + prefer_long * (lmax - ln) / lmax
        if score < best[0]:
            best = (score, s, ln, float(c[s]))
    return best[1], best[2], best[3]


def transition_map(frames: np.ndarray, start: int, length: int, transition: int, *, sigma: float = 3.0) -> np.ndarray:
    """Per-pixel transition frame ``tau (H, W)`` in ``[0, transition)`` (see the module docstring)."""
    import cv2

    o = transition
    h, w = frames.shape[1:3]
    cost = np.empty((o, h, w), np.float32)
    for j in range(o):
        d = frames[start + length + j].astype(np.float32) - frames[start + j].astype(np.float32)
        cost[j] = cv2.GaussianBlur((d * d).sum(axis=2), (0, 0), sigma)
    return np.argmin(cost, axis=0).astype(np.int32)


def looped_block(
    frames: np.ndarray,
    start: int,
    length: int,
    tau: np.ndarray,
    y: int,
    x: int,
    h: int,
    w: int,
    u: Sequence[int] | None = None,
) -> np.ndarray:
    """Frames ``u`` (default all ``0..L-1``) of the seamless loop, block ``[y:y+h, x:x+w]``, uint8."""
    u = np.arange(length) if u is None else np.asarray(u)
    tb = tau[y : y + h, x : x + w]
    out = np.empty((len(u), h, w, frames.shape[3]), np.uint8)
    tmax = int(tb.max()) if tb.size else 0
    for i, uu in enumerate(u):
        early = frames[start + uu, y : y + h, x : x + w]
        if uu >= tmax:  # every pixel has passed its transition
            out[i] = early
        else:
            out[i] = np.where((uu < tb)[..., None], frames[start + length + uu, y : y + h, x : x + w], early)
    return out


# -- 4. optical flow -----------------------------------------------------------------------------
def flow_magnitude(frames: np.ndarray, start: int, length: int, *, pairs: int = 6, max_side: int = 320) -> np.ndarray:
    """Mean Farneback optical-flow magnitude ``(H, W)`` in full-resolution pixels per frame."""
    import cv2

    t, h, w = frames.shape[:3]
    scale = min(1.0, max_side / max(h, w))
    size = (max(8, int(round(w * scale))), max(8, int(round(h * scale))))
    acc = np.zeros((size[1], size[0]), np.float32)
    idx = np.linspace(start, start + length - 2, min(pairs, length - 1)).round().astype(int)
    for i in idx:
        a = cv2.resize(grey(frames[i]), size, interpolation=cv2.INTER_AREA)
        b = cv2.resize(grey(frames[i + 1]), size, interpolation=cv2.INTER_AREA)
        f = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 15, 3, 5, 1.2, 0)
        acc += np.sqrt((f * f).sum(axis=2))
    acc /= max(1, len(idx))
    return cv2.resize(acc, (w, h), interpolation=cv2.INTER_LINEAR) / scale


class Texture:
    """One class's loop, flow and primary tile."""

    def __init__(self, frames, start, length, cost, tau, flow):
        self.frames, self.start, self.length, self.cost, self.tau, self.flow = frames, start, length, cost, tau, flow
        self.primary = None
        self.primary_pos = (0, 0)
        self.toroid_cost = (0.0, 0.0)
        self._activity = None

    def block(self, y, x, h, w, u=None):
        return looped_block(self.frames, self.start, self.length, self.tau, y, x, h, w, u)

    @property
    def activity(self) -> np.ndarray:
        """Mean squared consecutive-frame difference per pixel over the loop (a few pairs; once)."""
        if self._activity is None:
            f = self.frames
            idx = even_sample(self.length - 1, 8) + self.start
            acc = np.zeros(f.shape[1:3], np.float32)
            for i in idx:
                d = f[i + 1].astype(np.float32) - f[i].astype(np.float32)
                acc += (d * d).sum(axis=2)
            self._activity = acc / len(idx)
        return self._activity


def block_starts(extent: int, size: int, stride: int) -> np.ndarray:
    """Block starts every ``stride`` pixels along an axis of ``extent``, the last flush with its end."""
    return np.unique(np.r_[np.arange(0, extent - size + 1, stride), extent - size])


def lively_first(ranked: list) -> list:
    """Candidates sorted by cost, the calm ones (activity below half the median) last.

    Without this the lowest overlap error wins in the stillest part of the clip, and the
    tiles would show a texture calmer than the source.
    """
    med = float(np.median([r[3] for r in ranked]))
    return sorted(ranked, key=lambda r: (r[3] < 0.5 * med, r[0]))


def progress_steps(progress: Progress | None, total: int) -> Callable[[int], None]:
    """``step(k=1)``: ``k`` more of an analysis's ``total`` steps done, told to ``progress`` (never past ``total``)."""
    done = 0

    def step(k: int = 1) -> None:
        nonlocal done
        done += k
        if progress is not None:
            progress(min(done, total), total)

    return step
