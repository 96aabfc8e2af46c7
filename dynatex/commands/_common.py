"""Argument types and helpers shared by the subcommands."""
from __future__ import annotations

import argparse
import os
import sys
from typing import Callable

from ..cli import UsageError


def size_arg(text: str) -> tuple[int, int]:
    """``WxH`` -> (w, h)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, not {text!r}") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"size {text!r} out of range 1..16384")
    return w, h


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, not {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, not {text!r}")
    return v


def load_clip_arg(path: str, **options):
    """:func:`~dynatex.analyzer.video.load_clip` of a command-line clip: a ``.npy`` file is read
    as an array (no pickles), a video file is decoded in a child process (``isolate``)."""
    from ..analyzer.video import load_clip
    if path.endswith(".npy") and os.path.isfile(path):
        import numpy as np
        return load_clip(np.load(path, allow_pickle=False), **options)
    return load_clip(path, isolate=os.path.isfile(path), **options)


def tqdm_progress(desc: str, enabled: bool = True) -> Callable[[int, int | None], None] | None:
    """A ``progress(done, total)`` callback drawing a tqdm bar on stderr (None when disabled)."""
    if not enabled:
        return None
    from tqdm import tqdm
    bar = None

    def update(done: int, total: int | None) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, desc=desc, unit="it", file=sys.stderr, leave=False,
                       disable=not sys.stderr.isatty())
        if total is not None and bar.total != total:
            bar.total = total
        bar.n = done
        bar.refresh()
        if total is not None and done >= total:
            bar.close()

    return update


__all__ = ["UsageError", "load_clip_arg", "positive_int", "size_arg", "tqdm_progress"]
