"""The optional ``detail`` part of ``lds`` and ``mixture``: round trip, older databases without
it, a newer version ignored, damaged values refused with a clear error."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError

from ..conftest import wave_clip


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    clip = load_clip(wave_clip(60, h=20, w=28))
    path = tmp_path_factory.mktemp("detail") / "d.h5"
    lds = learn_lds(clip, n=5)
    mix = learn_mixture(clip, components=2, dim=3, pca_dim=12, neighbors=6, pmax=3)
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", lds)
        w.put_method("w", "mixture", mix)
    return path, {"lds": lds, "mixture": mix}


@pytest.mark.parametrize("method", ["lds", "mixture"])
def test_round_trip(db, method):
    path, models = db
    want = models[method].detail
    with TileDB(path) as t:
        got = t.texture("w").read(method).detail
    for name in ("volume", "gain", "low", "high", "colours"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert got.volume.dtype == np.int8 and got.low.dtype == np.uint8
    assert got.info["residual_energy"] == pytest.approx(want.info["residual_energy"])


def _copy(db, tmp_path, edit):
    path, _ = db
    out = tmp_path / "c.h5"
    out.write_bytes(path.read_bytes())
    with h5py.File(out, "a") as f:
        edit(f["textures/w/lds"])
    return out


def _read(path):
    with TileDB(path) as t:
        return t.texture("w").read("lds")


def test_absent_part_reads_as_none(db, tmp_path):
    assert _read(_copy(db, tmp_path, lambda g: g.__delitem__("detail"))).detail is None


def test_newer_version_is_ignored(db, tmp_path):
    def newer(g):
        g["detail"].attrs["version"] = 99

    assert _read(_copy(db, tmp_path, newer)).detail is None


def _replace(name, fn):
    def edit(g):
        data = fn(g["detail"][name][()])
        del g["detail"][name]
        g["detail"].create_dataset(name, data=data)

    return edit


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
def test_damaged_detail_is_refused(db, tmp_path, name, fn, match):
    with pytest.raises(TileDBFormatError, match=match):
        _read(_copy(db, tmp_path, _replace(name, fn)))
