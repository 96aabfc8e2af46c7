"""Opening and validating tile databases, including damaged and hostile files."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dynatex.tiledb import (
    FORMAT_VERSION,
    MethodNotFoundError,
    TextureNotFoundError,
    TileDBError,
    TileDBFormatError,
    TileDBNotFoundError,
    TileDBVersionError,
    open_db,
)
from dynatex.tiledb.schema import COMPATIBLE_VERSION


def test_open_lists_textures_and_reads_lds(lds_db):
    with open_db(lds_db) as db:
        assert db.textures == ("waves",)
        assert db.version == COMPATIBLE_VERSION == (1, 8)  # no tone part: every 1.x reader reads it
        tex = db.texture()  # the only one
        assert tex.methods == ("lds",)
        m = tex.read("lds")
        assert m.basis.shape == (12, 24 * 32 * 3)
        assert m.basis.dtype == np.float32
        np.testing.assert_allclose(m.basis @ m.basis.T, np.eye(12), atol=1e-4)


def test_missing_file(tmp_path):
    with pytest.raises(TileDBNotFoundError) as e:
        open_db(tmp_path / "nope.h5")
    assert isinstance(e.value, FileNotFoundError)
    assert "nope.h5" in str(e.value)


def test_not_hdf5(tmp_path):
    p = tmp_path / "x.h5"
    p.write_bytes(b"this is not an HDF5 file at all" * 10)
    with pytest.raises(TileDBFormatError, match="not a readable HDF5 file"):
        open_db(p)


def test_truncated(lds_db, tmp_path):
    data = lds_db.read_bytes()
    p = tmp_path / "cut.h5"
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(TileDBError) as e:
        with open_db(p) as db:
            db.validate()
    assert "cut.h5" in str(e.value)
    assert "\n" not in str(e.value)


def test_not_a_dynatex_file(tmp_path):
    p = tmp_path / "other.h5"
    with h5py.File(p, "w") as f:
        f["x"] = 1
    with pytest.raises(TileDBFormatError, match="not a dynatex tile database"):
        open_db(p)


def test_future_major_version_refused_minor_accepted(lds_db):
    for version in ((1, 9), FORMAT_VERSION, (2, 5)):
        with h5py.File(lds_db, "a") as f:
            f.attrs["format_version"] = np.array(version, np.int32)
        with open_db(lds_db) as db:
            assert db.version == version
    with h5py.File(lds_db, "a") as f:
        f.attrs["format_version"] = np.array([3, 0], np.int32)
    with pytest.raises(TileDBVersionError, match=r"format version 3.0 is not supported .*reads major versions 1-2\)"):
        open_db(lds_db)


def test_unknown_texture_and_method(lds_db):
    with open_db(lds_db) as db:
        with pytest.raises(TextureNotFoundError, match="no texture named 'fire'.*available: waves") as e:
            db.texture("fire")
        assert isinstance(e.value, KeyError)
        assert str(e.value).startswith(str(lds_db))  # not quoted like a plain KeyError
        with pytest.raises(MethodNotFoundError, match="has no 'turnpoints' data"):
            db.texture("waves").read("turnpoints")
        with pytest.raises(ValueError, match="method must be one of"):
            db.texture("waves").read("bogus")


@pytest.mark.parametrize(
    "path, value, message",
    [
        ("lds/A", lambda a: a * 10, "not stable"),
        ("lds/mean", lambda a: np.full_like(a, np.nan), "NaN"),
        ("lds/basis", lambda a: a[:, :-1], "has shape"),
        ("lds/B", lambda a: a.astype(np.int32), "not floating point"),
    ],
)
def test_corrupt_lds_named_precisely(lds_db, path, value, message):
    full = f"textures/waves/{path}"
    with h5py.File(lds_db, "a") as f:
        arr = f[full][()]
        del f[full]
        f[full] = value(arr)
    with open_db(lds_db) as db:
        with pytest.raises(TileDBFormatError, match=message) as e:
            db.texture("waves").read("lds")
    assert f"/{full}" in str(e.value) and str(lds_db) in str(e.value)


def test_hostile_attribute_types(lds_db):
    with h5py.File(lds_db, "a") as f:
        f["textures/waves/source"].attrs["width"] = "wide"
    with pytest.raises(TileDBFormatError, match="@width.*invalid value"):
        open_db(lds_db)


def test_missing_source_group(lds_db):
    with h5py.File(lds_db, "a") as f:
        del f["textures/waves/source"]
    with pytest.raises(TileDBFormatError, match="/textures/waves/source: missing group"):
        open_db(lds_db)
