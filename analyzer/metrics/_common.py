"""What the metric families share: option checks, luma, downscaling, the reference frame step."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...checks import Range, check_int
from ...errors import ArgumentTypeError, InvalidArgumentError
from ...framestats import LUMA, float_chunks, median_step
from .memo import remembered

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


@remembered
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


@remembered
def reference_step(frames: np.ndarray, name: str) -> float:
    """The typical frame step of ``frames`` (:func:`~dynatex.framestats.median_step`), which
    measures divide by: an error naming ``name`` when it is 0 (the clip is still)."""
    ref = median_step(frames)
    if ref <= 0:
        raise InvalidArgumentError(f"{name} does not change from frame to frame (median frame difference is 0)")
    return ref


def json_float(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None
