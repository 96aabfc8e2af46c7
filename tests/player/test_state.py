"""Saved states restore all or nothing: a state with one bad entry is refused with a clear
error and leaves the player exactly as it was, in every mode."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.player import open_player
from dynatex.player.opencl import selftest

MODES = [
    ("lds", {}),
    ("mixture", {}),
    ("turnpoints", {"playback": "jumps"}),
    ("tiles", {"size": (72, 40)}),
    ("evolve", {"jitter": 2.0}),
]
BAD_VALUES = ["bad", float("nan"), -1]


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
    return a == b or (a != a and b != b)


@pytest.mark.parametrize("mode, options", MODES, ids=[m for m, _ in MODES])
def test_a_state_with_one_bad_entry_changes_nothing(mode, options):
    db = selftest._db_path()
    with (
        open_player(db, selftest.TEXTURE, mode=mode, backend="numpy", seed=3, **options) as p,
        open_player(db, selftest.TEXTURE, mode=mode, backend="numpy", seed=9, **options) as other,
    ):
        for _ in range(3):
            p.next_frame()
            other.next_frame()
        if mode == "evolve":
            other.rate_map = np.full(other.shape[:2], 2.0, np.float32)  # a state that rebuilds tables
        saved = other.get_state()
        before = p.get_state()
        refused = 0
        for key in saved:
            if key in ("mode", "texture"):
                continue
            for bad_value in BAD_VALUES:
                bad = dict(saved)
                bad[key] = bad_value
                try:
                    p.set_state(bad)
                except (ValueError, TypeError):
                    refused += 1
                    assert _same(p.get_state(), before), (mode, key, bad_value)
                    continue
                p.set_state(before)  # a value that is valid for this entry (e.g. -1 as a direction)
        assert refused >= len(saved) - 2
        want = [p.next_frame() for _ in range(3)]
    with open_player(db, selftest.TEXTURE, mode=mode, backend="numpy", seed=3, **options) as q:
        q.set_state(before)
        for k, frame in enumerate(want):
            assert np.array_equal(q.next_frame(), frame), (mode, k)
