"""Parts of the metrics computed once while several outputs are judged against one source.

:func:`~dynatex.analyzer.metrics.evaluate` runs nine metrics that each take the luma of both
clips, and ``--methods auto`` judges four or five outputs against one source: the source's luma,
spectrum, patch model, colour set and frame steps are the same every time. Inside :func:`remembering` a function
marked :func:`remembered` computes each result once per argument set, when every array it is
given lies within the memory of an array the block (or a block around it) remembers; the result
becomes one of the block's arrays too, so what is computed from it is remembered as well. A
block's results are dropped when it ends: an outer block over the source keeps the source's
parts for every output, an inner one over an output keeps that output's parts for one report.

Arrays are told apart by their memory and layout (address, shape, strides, dtype), so two views
of one clip's frames are one argument. Remembered arrays must not change inside the block;
results are returned read-only.
"""

from __future__ import annotations

import contextvars
import functools
import inspect
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])


class _Block:
    def __init__(self, parent: _Block | None, arrays: tuple[np.ndarray, ...]) -> None:
        self.parent = parent
        self.arrays: list[np.ndarray] = []  # kept alive: their addresses stay theirs while the block lives
        self.bounds: list[tuple[int, int]] = []
        self.results: dict[tuple, Any] = {}
        for a in arrays:
            self.hold(a)

    def hold(self, a: np.ndarray) -> None:
        self.arrays.append(a)
        self.bounds.append(_bounds(a))

    def holds(self, span: tuple[int, int]) -> bool:
        return any(lo <= span[0] and span[1] <= hi for lo, hi in self.bounds)

    def chain(self) -> list[_Block]:
        """This block and those around it, outermost first."""
        out, b = [], self
        while b is not None:
            out.append(b)
            b = b.parent
        return out[::-1]


_BLOCK: contextvars.ContextVar[_Block | None] = contextvars.ContextVar("dynatex_metrics_memo", default=None)


@contextmanager
def remembering(*arrays: Any) -> Iterator[None]:
    """Within the block, :func:`remembered` parts computed from ``arrays`` are computed once.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (20, 32, 32, 3)).astype(np.uint8)
    >>> from .likeness import spectrum_distance
    >>> halves = clip[:10], clip[10:]
    >>> with remembering(clip):  # the source's spectrum computed for the first half, reused for the second
    ...     shared = [spectrum_distance(h, clip, cuboid=(8, 16)) for h in halves]
    >>> shared == [spectrum_distance(h, clip, cuboid=(8, 16)) for h in halves]
    True
    """
    block = _Block(_BLOCK.get(), tuple(a for a in arrays if isinstance(a, np.ndarray)))
    token = _BLOCK.set(block)
    try:
        yield
    finally:
        _BLOCK.reset(token)


def remembered(fn: F) -> F:
    """Mark ``fn`` (arrays and plain values in, a result that is never changed out) as one whose
    results :func:`remembering` keeps; a call with another kind of argument is not kept."""
    signature = inspect.signature(fn)

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        block = _BLOCK.get()
        if block is None:
            return fn(*args, **kwargs)
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        values = tuple(bound.arguments.items())
        spans = [_bounds(v) for _, v in values if isinstance(v, np.ndarray)]
        chain = block.chain()
        home = next((b for b in chain if all(any(c.holds(s) for c in b.chain()) for s in spans)), None)
        if home is None:
            return fn(*args, **kwargs)
        if not all(isinstance(v, np.ndarray) or _plain(v) for _, v in values):
            return fn(*args, **kwargs)
        key = (fn,) + tuple((k, _key(v)) for k, v in values)
        if key in home.results:
            return home.results[key]
        result = _read_only(fn(*args, **kwargs), spans)
        home.results[key] = result
        for a in _arrays(result):
            home.hold(a)
        return result

    return wrapper  # type: ignore[return-value]


def _bounds(a: np.ndarray) -> tuple[int, int]:
    """The first and one-past-last byte addresses ``a`` can read."""
    lo = hi = a.__array_interface__["data"][0]
    if a.size == 0:
        return lo, lo
    for n, s in zip(a.shape, a.strides):
        (lo, hi) = (lo + s * (n - 1), hi) if s < 0 else (lo, hi + s * (n - 1))
    return lo, hi + a.itemsize


def _plain(v: Any) -> bool:
    """Whether ``v`` is a value that keys a result by what it is (not an object by its id)."""
    if isinstance(v, tuple):
        return all(_plain(x) for x in v)
    return v is None or isinstance(v, (bool, int, float, str, np.integer, np.floating))


def _key(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return ("array", v.__array_interface__["data"][0], v.shape, v.strides, v.dtype.str)
    return v


def _arrays(result: Any) -> list[np.ndarray]:
    if isinstance(result, np.ndarray):
        return [result]
    if isinstance(result, tuple):
        return [a for r in result for a in _arrays(r)]
    return []


def _read_only(result: Any, spans: list[tuple[int, int]]) -> Any:
    """``result`` with its arrays made read-only, but for those within an argument's memory (a
    view of an argument stays as the caller made it)."""
    for a in _arrays(result):
        lo, hi = _bounds(a)
        if not any(s[0] <= lo and hi <= s[1] for s in spans):
            a.flags.writeable = False
    return result
