"""What the metric families share: option checks, float chunks, luma, downscaling, frame steps."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...checks import Range, check_int
from ...errors import ArgumentTypeError, InvalidArgumentError

LUMA = np.array([0.299, 0.587, 0.114], np.float32)
CHUNK = 32  # frames converted to float at a time (bounds memory on long clips)
THUMB = 32  # longer side of the thumbnails used by coverage and repetition


#: a positive finite number (eps, floors, tolerances)
POSITIVE = Range(float, 0.0, None, low_open=True)


def int_pair(name: str, value: Any, lo: int) -> tuple[int, int]:
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (value, value)
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{name} must be an integer or a pair of integers, not {value!r}") from None
    return check_int(f"{name}[0]", a, lo), check_int(f"{name}[1]", b, lo)


def same_size(a: np.ndarray, b: np.ndarray, what: str) -> None:
    if a.shape[1:3] != b.shape[1:3]:
        raise InvalidArgumentError(
            f"{what} needs output and source of the same frame size; output is "
            f"{a.shape[2]}x{a.shape[1]}, source {b.shape[2]}x{b.shape[1]}"
        )


def float_chunks(frames: np.ndarray, start: int = 0, stop: int | None = None):
    stop = frames.shape[0] if stop is None else stop
    for i in range(start, stop, CHUNK):
        yield i, frames[i : min(i + CHUNK, stop)].astype(np.float32)


def luma(frames: np.ndarray, factor: int = 1, size: tuple[int, int] | None = None) -> np.ndarray:
    """``(T, H', W')`` float32 luma, area-downscaled by ``factor`` (or to ``size`` = (H', W'))."""
    import cv2

    t, h, w, c = frames.shape
    if size is None:
        size = (max(1, h // factor), max(1, w // factor))
    out = np.empty((t,) + tuple(size), np.float32)
    for i, chunk in float_chunks(frames):
        g = chunk[..., 0] if c == 1 else chunk @ LUMA
        if size == (h, w):
            out[i : i + len(g)] = g
        else:
            for k in range(len(g)):
                out[i + k] = cv2.resize(g[k], (size[1], size[0]), interpolation=cv2.INTER_AREA)  # cv2: (w, h)
    return out


def auto_downscale(source: np.ndarray, downscale: int | None) -> int:
    if downscale is None:
        return max(1, min(source.shape[1], source.shape[2]) // 128)
    return check_int("downscale", downscale, 1)


def thumb_size(shape: tuple[int, ...]) -> tuple[int, int]:
    h, w = shape[1], shape[2]
    s = min(1.0, THUMB / max(h, w))
    return max(1, round(h * s)), max(1, round(w * s))


def step_rms(frames: np.ndarray) -> np.ndarray:
    """RMS difference (grey levels, over pixels and channels) between consecutive frames, ``(T-1,)``."""
    t = frames.shape[0]
    out = np.empty(max(t - 1, 0), np.float64)
    prev = None
    for i, chunk in float_chunks(frames):
        if prev is not None:
            chunk = np.concatenate([prev, chunk])
            first = i - 1
        else:
            first = i
        d = np.diff(chunk, axis=0).reshape(chunk.shape[0] - 1, -1)
        out[first : first + len(d)] = np.sqrt(np.einsum("ij,ij->i", d, d, dtype=np.float64) / d.shape[1])
        prev = chunk[-1:]
    return out


def median_step(frames: np.ndarray, name: str) -> float:
    steps = step_rms(frames)
    ref = float(np.median(steps))
    if ref <= 0:
        raise InvalidArgumentError(f"{name} does not change from frame to frame (median frame difference is 0)")
    return ref


def json_float(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None
