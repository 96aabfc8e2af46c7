"""The metrics' memo: a source's parts computed once across outputs, with the same figures."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer.metrics import evaluate
from dynatex.analyzer.metrics.memo import remembered, remembering

CALLS: list[int] = []


@remembered
def _total(frames: np.ndarray, scale: int = 1) -> np.ndarray:
    CALLS.append(scale)
    if scale < 0:
        raise ValueError("scale must be >= 0")
    return frames.sum(axis=0) * scale


@pytest.fixture
def clip() -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (40, 24, 32, 3)).astype(np.uint8)


def test_a_block_computes_each_part_once_and_returns_it_read_only(clip: np.ndarray) -> None:
    CALLS.clear()
    with remembering(clip):
        a = _total(clip)
        b = _total(clip, 1)  # the same arguments, bound to the signature
        c = _total(clip[..., :], scale=1)  # another view of the same memory and layout
        _total(clip, 2)
    assert a is b is c and len(CALLS) == 2
    assert not a.flags.writeable
    with pytest.raises(ValueError):
        a[0, 0, 0] = 1


def test_without_a_block_or_outside_its_arrays_nothing_is_kept(clip: np.ndarray) -> None:
    CALLS.clear()
    _total(clip)
    _total(clip)
    other = clip.copy()
    with remembering(clip):
        _total(other)
        _total(other)
        _total(clip[:10])  # a view inside the remembered memory is remembered
        _total(clip[:10])
    assert len(CALLS) == 5
    assert _total(clip).flags.writeable


def test_an_inner_block_drops_its_parts_and_the_outer_keeps_its_own(clip: np.ndarray) -> None:
    CALLS.clear()
    out = clip[::-1].copy()
    with remembering(clip):
        for _ in range(3):
            with remembering(out):
                _total(clip)
                _total(out)
                _total(out)
    assert CALLS == [1, 1, 1, 1]  # the source's once, the output's once per inner block


def test_parts_of_parts_are_remembered_and_failures_are_not(clip: np.ndarray) -> None:
    CALLS.clear()
    with remembering(clip):
        assert _total(_total(clip)) is _total(_total(clip))
    assert len(CALLS) == 2
    CALLS.clear()
    with remembering(clip):
        for _ in range(2):
            with pytest.raises(ValueError, match="scale"):
                _total(clip, scale=-1)
    assert CALLS == [-1, -1]


def test_evaluate_gives_the_same_report_with_the_source_remembered(clip: np.ndarray) -> None:
    rng = np.random.default_rng(1)
    outputs = [np.clip(clip.astype(int) + rng.integers(-30, 30, clip.shape), 0, 255).astype(np.uint8) for _ in range(2)]
    alone = [evaluate(o, clip, window=10, n_samples=200) for o in outputs]
    with remembering(clip):
        shared = [evaluate(o, clip, window=10, n_samples=200) for o in outputs]
        again = evaluate(outputs[0], clip, window=10, n_samples=200)
    assert shared == alone and again == alone[0]
    assert alone[0] != alone[1]
