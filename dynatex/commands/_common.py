"""Argument types and helpers shared by the subcommands."""
from __future__ import annotations

import argparse
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


__all__ = ["UsageError", "positive_int", "size_arg", "tqdm_progress"]
