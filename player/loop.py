"""Closed loops of any mode: frames whose last leads into the first as any other step does.

Shared by ``dynatex export --loop``, ``dynatex play --loop`` and
:meth:`Player.frames(count, loop=True) <dynatex.player.base.Player.frames>`. A mode whose
frames repeat after a loop of its own (``capabilities.native_loop``) closes that loop itself,
in its ``_native_loop`` (tiles: the tile loop at the speed that fits whole loops into the
frames; turnpoints: the longest swing between two consecutive turn points and back); for every
other mode (lds, mixture, evolve) ``count + blend`` frames are rendered and the last ``blend``
are crossfaded into the first ``blend``, so the frame after the last is the sequence's own
next frame.

With ``keep_pace`` the native loops play at the source's pace (one source frame per output
frame, no blending) and repeat the whole number of times nearest ``count`` frames, so the
frame count is that many loops, and the frames start after the cycle's smallest step (a
rotation of the cycle: a video player that stalls at the wrap does so where least moves);
without it (a flipbook) ``count`` frames hold one loop, at
whatever pace that takes.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InvalidArgumentError
from ..framestats import median_step


def loop_frames(
    player, count: int | None = None, *, blend: int | None = None, keep_pace: bool = False
) -> tuple[np.ndarray, str, float]:
    """``(frames, how, pace)``: frames ``(N, H, W, C)`` forming a closed loop (``count`` of them,
    or with ``keep_pace`` a native loop's whole loops nearest ``count``), a
    description of the method, and the source frames each output frame advances (1 at the
    source's pace).

    ``count`` defaults to the mode's own loop (tiles' loop length, turnpoints' swing) or 64;
    ``blend`` (modes without a loop of their own) defaults to a quarter of ``count``. A native
    loop leaves the player's ``epoch`` and ``speed`` (tiles) changed.
    """
    if count is not None and (isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1):
        raise InvalidArgumentError(f"count must be a positive integer, not {count!r}")
    native = type(player).capabilities.native_loop
    if blend is not None and native:
        raise InvalidArgumentError(f"blend belongs to modes without a loop of their own, not {player.mode}")
    if native:
        frames, how, pace = player._native_loop(count, keep_pace)
        if keep_pace and len(frames) > 2:
            # a cycle: start the file after its smallest step, where a player's wrap shows least
            frames = np.roll(frames, -(_smallest_step(frames) + 1), axis=0)
            how += ", starting after its smallest step"
        return frames, how, pace
    n = int(count) if count is not None else 64
    blend = blend if blend is not None else max(1, n // 4)
    if not 1 <= blend < n:
        raise InvalidArgumentError(f"blend {blend} must be 1 to fewer than the {n} frames")
    frames = crossfade_loop(render(player, n + blend), n, blend)
    return frames, f"crossfade of the last {blend} of {n + blend} frames into the first {blend}", 1.0


def _smallest_step(frames: np.ndarray) -> int:
    """``k`` whose step to frame ``k + 1`` (the last's to the first) is the smallest."""
    n = len(frames)
    steps = np.empty(n)
    for k in range(n):
        d = (frames[(k + 1) % n].astype(np.int64) - frames[k]).ravel()
        steps[k] = float(np.dot(d, d))
    return int(np.argmin(steps))


def render(player, n: int) -> np.ndarray:
    """The player's next ``n`` frames, ``(n, H, W, C)``."""
    frames = np.empty((n,) + tuple(player.shape), np.uint8)
    for k in range(n):
        player.next_frame(out=frames[k])
    return frames


def repeats(length: int, count: int | None, keep_pace: bool) -> tuple[int, int]:
    """(frames, whole loops in them): ``count`` frames holding one loop, or with ``keep_pace``
    the whole loops nearest ``count`` at one source frame per output frame."""
    if count is None:
        return length, 1
    if keep_pace:
        loops = max(1, round(count / length))
        return length * loops, loops
    return int(count), 1


def crossfade_loop(frames: np.ndarray, n: int, blend: int) -> np.ndarray:
    """``frames[:n]`` with ``frames[n:n + blend]`` faded into its start: frame ``n`` follows frame ``n - 1``.

    Examples
    --------
    >>> ramp = np.arange(0, 60, 10, dtype=np.uint8)[:, None]      # frames 0, 10, ..., 50
    >>> crossfade_loop(ramp, 4, 2)[:, 0].tolist()                 # 40 and 50 faded into 0 and 10
    [27, 23, 20, 30]
    """
    out = frames[:n].copy()
    w = (np.arange(1, blend + 1) / (blend + 1)).reshape((-1,) + (1,) * (frames.ndim - 1))
    out[:blend] = np.rint((1 - w) * frames[n : n + blend] + w * frames[:blend]).astype(np.uint8)
    return out


__all__ = ["crossfade_loop", "loop_frames", "render", "repeats"]


def wrap_report(frames: np.ndarray, source: np.ndarray | None) -> dict:
    """The wrap of the closed loop ``frames`` (last frame -> first) as ``{"ratio", "reference"}``:
    their RMS difference over the median frame step of ``source`` (of ``frames`` when None or one
    frame), as :func:`dynatex.analyzer.metrics.temporal_discontinuity` measures a jump; the ratio
    is None, the reference saying why, for one frame or a reference that never changes.

    >>> ramp = np.repeat(np.arange(0, 40, 2, dtype=np.uint8), 4).reshape(20, 2, 2)
    >>> wrap_report(ramp[:10], ramp)
    {'ratio': 9.0, 'reference': 'median frame step of the source'}
    """
    if len(frames) < 2:
        return {"ratio": None, "reference": "one frame: no wrap"}
    name = "export" if source is None or len(source) < 2 else "source"
    step = median_step(frames if name == "export" else source)
    if not step > 0:
        return {
            "ratio": None,
            "reference": f"the {name} does not change from frame to frame (median frame difference is 0)",
        }
    d = frames[0].astype(np.float64) - frames[-1].astype(np.float64)
    return {"ratio": round(math.sqrt(float(np.mean(d * d))) / step, 4), "reference": f"median frame step of the {name}"}
