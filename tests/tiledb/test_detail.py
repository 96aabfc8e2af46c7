"""The optional ``detail`` part of ``lds`` and ``mixture``: round trip, older databases without
it, a newer version ignored, damaged values refused with a clear error."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.tiledb import TileDB, TileDBFormatError

from .conftest import edited_copy, replace_dataset


@pytest.mark.parametrize("method", ["lds", "mixture"])
def test_round_trip(projection_db, method):
    want = projection_db.models[method].detail
    got = projection_db.read(method).detail
    for name in ("volume", "gain", "low", "high", "colours"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert got.volume.dtype == np.int8 and got.low.dtype == np.uint8
    assert got.info["residual_energy"] == pytest.approx(want.info["residual_energy"])


def _copy(projection_db, tmp_path, edit):
    return edited_copy(projection_db.path, tmp_path, "textures/w/lds", edit)


def _read(path):
    with TileDB(path) as t:
        return t.texture("w").read("lds")


def test_absent_part_reads_as_none(projection_db, tmp_path):
    assert _read(_copy(projection_db, tmp_path, lambda g: g.__delitem__("detail"))).detail is None


def test_newer_version_is_ignored(projection_db, tmp_path):
    def newer(g):
        g["detail"].attrs["version"] = 99

    assert _read(_copy(projection_db, tmp_path, newer)).detail is None


@pytest.mark.parametrize(
    ("name", "fn", "match"),
    [
        ("gain", lambda a: a * np.nan, "NaN"),
        ("gain", lambda a: a - 1, "outside 0..16"),
        ("low", lambda a: np.full_like(a, 255), "low <= high"),
        ("low", lambda a: a.astype(np.uint16), "low: dtype uint16 is not uint8"),
        ("high", lambda a: a.astype(np.uint16), "high: dtype uint16 is not uint8"),
        ("volume", lambda a: a.astype(np.int16), "int8"),
        ("volume", lambda a: a[..., :1], "expected"),
        ("volume", lambda a: np.zeros((300,) + a.shape[1:], np.int8), r"expected \(1\.\.256, "),
        ("high", lambda a: a[:-1], "expected"),
        ("colours", lambda a: a * 2, "0 or 1"),
        ("colours", lambda a: a[:-1], "expected"),
    ],
)
def test_damaged_detail_is_refused(projection_db, tmp_path, name, fn, match):
    with pytest.raises(TileDBFormatError, match=match):
        _read(_copy(projection_db, tmp_path, replace_dataset(f"detail/{name}", fn)))


@pytest.mark.parametrize("value", ["", "0.2", [0.1, 0.2]])
def test_the_residual_energy_must_be_a_number(projection_db, tmp_path, value):
    """``dynatex info`` shows it as a number: anything else is refused in one line, naming it."""

    def bad(g):
        g["detail"].attrs["residual_energy"] = value

    path = _copy(projection_db, tmp_path, bad)
    with pytest.raises(TileDBFormatError, match="detail@residual_energy") as e:
        _read(path)
    assert "\n" not in str(e.value)
