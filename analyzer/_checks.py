"""Argument checks shared by the analyzer modules: integers, sizes and clips of frames."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..tiledb.errors import DynatexError


class ArgumentTypeError(DynatexError, TypeError, ValueError):
    """An argument of the wrong type. Also a ValueError: to a caller it is one more bad value."""


def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None, *,
              rule: str | None = None) -> int:
    """``value`` as an int in ``[lo, hi]`` (either bound may be None).

    Raises :class:`ArgumentTypeError` naming ``name`` when ``value`` is not an integer (bools
    are refused), and a ValueError ``"{name} must be {rule}, not {value}"`` when it is out of
    range. ``rule`` defaults to words for the bounds ("a non-negative integer",
    "an integer >= 1", "an integer in [1, 8]"); pass it where a bound has a name (``"an
    integer in 1..n=5"``).

    Examples
    --------
    >>> check_int("n", np.int64(3), 1)
    3
    >>> check_int("n", 0, 1)
    Traceback (most recent call last):
    ...
    ValueError: n must be an integer >= 1, not 0
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ArgumentTypeError(f"{name} must be an integer, not {value!r}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        if rule is None:
            if hi is None:
                rule = "a non-negative integer" if lo == 0 else f"an integer >= {lo}"
            elif lo is None:
                rule = f"an integer <= {hi}"
            else:
                rule = f"an integer in [{lo}, {hi}]"
        raise ValueError(f"{name} must be {rule}, not {v}")
    return v


def check_size(name: str, value: Any, max_side: int) -> tuple[int, int]:
    """``value`` as a ``(height, width)`` pair of integers, each in ``1..max_side``.

    The player's check of the same name, with this module's :class:`ArgumentTypeError` for
    a value that is not a pair of integers; a ValueError for another length or a side out of range.

    Examples
    --------
    >>> check_size("size", (24, np.int64(40)), 100)
    (24, 40)
    """
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ArgumentTypeError(f"{name} must be (height, width), not {value!r}")
    if len(value) != 2:
        raise ValueError(f"{name} must be (height, width), two integers, not {len(value)} values {value!r}")
    if any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in value):
        raise ArgumentTypeError(f"{name} must be (height, width) integers, not {value!r}")
    h, w = int(value[0]), int(value[1])
    if not (1 <= h <= max_side and 1 <= w <= max_side):
        raise ValueError(f"{name} must be (height, width) with each side in 1..{max_side}, not {value!r}")
    return h, w


def clip_frames(clip: Any) -> np.ndarray:
    """The ``(T, H, W, C)`` uint8 frames of a :class:`~.video.Clip` or an array, else a ValueError."""
    from .video import Clip  # video imports this module
    frames = clip.frames if isinstance(clip, Clip) else np.asarray(clip)
    if frames.ndim != 4 or frames.dtype != np.uint8:
        raise ValueError(f"clip must be (T, H, W, C) uint8 frames, not {frames.dtype} {frames.shape}")
    return frames
