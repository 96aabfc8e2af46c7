"""Sizes are ``(height, width)`` in every mode, like a frame's shape, and a bad size is the same error everywhere."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.checks import check_size
from dynatex.player import open_player
from dynatex.player.opencl import selftest

BAD_SIZES = [
    ((0, 10), ValueError, r"size must be \(height, width\) with each side in 1\.\.16384"),
    ((10, 20000), ValueError, r"size must be \(height, width\) with each side in 1\.\.16384"),
    ((10,), ValueError, r"size must be \(height, width\), two integers"),
    ((10, 20, 3), ValueError, r"size must be \(height, width\), two integers"),
    ((10.0, 20), TypeError, r"size must be \(height, width\) integers"),
    ((True, 20), TypeError, r"size must be \(height, width\) integers"),
    ("40x24", TypeError, r"size must be \(height, width\)"),
    (40, TypeError, r"size must be \(height, width\)"),
]


def test_check_size_returns_height_width_as_ints():
    assert check_size("size", (np.int32(24), 40), 100) == (24, 40)
    assert check_size("size", np.array([3, 5]), 5) == (3, 5)
    with pytest.raises(ValueError, match=r"out must be \(height, width\) with each side in 1\.\.5"):
        check_size("out", (3, 6), 5)


def test_tiles_frames_are_size_high_and_wide():
    with open_player(selftest._db_path(), selftest.TEXTURE, mode="tiles", size=(24, 40), backend="numpy") as p:
        assert p.shape[:2] == (24, 40) and p.next_frame().shape == (24, 40, 3)


def test_evolve_size_is_the_quilts_height_width():
    db = selftest._db_path()
    with open_player(db, selftest.TEXTURE, mode="evolve", backend="numpy") as p:
        h, w = p.texture.read("quilt").size
        assert h != w and p.shape[:2] == (h, w) and p.next_frame().shape == (h, w, 3)
    with open_player(db, selftest.TEXTURE, mode="evolve", size=(h, w), backend="numpy") as p:
        assert p.shape[:2] == (h, w)
    with pytest.raises(ValueError, match="does not fit the stored quilt"):
        open_player(db, selftest.TEXTURE, mode="evolve", size=(w, h), backend="numpy")


@pytest.mark.parametrize("mode", ["tiles", "evolve"])
@pytest.mark.parametrize("size, error, message", BAD_SIZES, ids=[repr(s) for s, _, _ in BAD_SIZES])
def test_a_bad_size_is_the_same_error_in_every_mode(mode, size, error, message):
    with pytest.raises(error, match=message):
        open_player(selftest._db_path(), selftest.TEXTURE, mode=mode, size=size, backend="numpy")
