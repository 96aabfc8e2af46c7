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


def test_arguments_keep_their_flags_and_objects_are_not_keys(clip: np.ndarray) -> None:
    @remembered
    def same(frames: np.ndarray) -> np.ndarray:
        return frames[:5]

    @remembered
    def scaled(frames: np.ndarray, by: object) -> float:
        CALLS.append(0)
        return float(frames.mean()) * len(str(by))

    CALLS.clear()
    with remembering(clip):
        assert same(clip).flags.writeable  # a view of the caller's array stays as the caller made it
        scaled(clip, 2)
        scaled(clip, 2)
        scaled(clip, [2])  # a list: not a value to key by
        scaled(clip, [2])
    assert clip.flags.writeable and len(CALLS) == 3


def test_evaluate_takes_the_sources_parts_once_across_outputs(clip: np.ndarray, monkeypatch) -> None:
    from dynatex.analyzer.metrics import _common, likeness

    counts = {"median_step": 0, "_patches": 0}
    for module, name in ((_common, "median_step"), (likeness, "_patches")):
        original = getattr(module, name)

        def counted(*a, _original=original, _name=name, **kw):
            counts[_name] += 1
            return _original(*a, **kw)

        monkeypatch.setattr(module, name, counted)
    rng = np.random.default_rng(2)
    outputs = [np.clip(clip.astype(int) + rng.integers(-30, 30, clip.shape), 0, 255).astype(np.uint8) for _ in range(3)]
    for o in outputs:
        evaluate(o, clip, window=10, n_samples=100)
    alone = dict(counts)
    counts.update(median_step=0, _patches=0)
    with remembering(clip):
        for o in outputs:
            evaluate(o, clip, window=10, n_samples=100)
    assert alone == {"median_step": 3, "_patches": 6}  # each report: the source's step, both clips' patches
    assert counts == {"median_step": 1, "_patches": 4}


def test_evaluate_gives_the_same_report_with_the_source_remembered(clip: np.ndarray) -> None:
    rng = np.random.default_rng(1)
    outputs = [np.clip(clip.astype(int) + rng.integers(-30, 30, clip.shape), 0, 255).astype(np.uint8) for _ in range(2)]
    alone = [evaluate(o, clip, window=10, n_samples=200) for o in outputs]
    with remembering(clip):
        shared = [evaluate(o, clip, window=10, n_samples=200) for o in outputs]
        again = evaluate(outputs[0], clip, window=10, n_samples=200)
    assert shared == alone and again == alone[0]
    assert alone[0] != alone[1]
