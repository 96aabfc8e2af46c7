"""Atomic writes: several textures per file, replace one, keep the others, never a partial file."""

from __future__ import annotations

import os

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.tiledb import DatabaseWriter, TileDBFormatError, open_db

from ..conftest import wave_clip


def _files(folder):
    return sorted(os.listdir(folder))


def test_add_texture_keeps_others(lds_db):
    clip = load_clip(wave_clip(t=30, h=16, w=16, seed=5))
    before = open_db(lds_db)
    basis_before = before.texture("waves").read("lds").basis.copy()
    before.close()
    with DatabaseWriter(lds_db) as w:
        w.put_texture("second", clip.source_info())
        w.put_method("second", "lds", learn_lds(clip, n=5))
        w.put_frames("second", clip.frames)
    with open_db(lds_db) as db:
        assert db.textures == ("second", "waves")
        np.testing.assert_array_equal(db.texture("waves").read("lds").basis, basis_before)
        store = db.texture("second").frames()
        assert len(store) == 30
        np.testing.assert_array_equal(store[3], clip.frames[3])
    assert _files(lds_db.parent) == ["waves.h5"]  # no temporary file left


def test_replace_texture(lds_db):
    clip = load_clip(wave_clip(t=30, h=16, w=16, seed=5))
    with DatabaseWriter(lds_db) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "lds", learn_lds(clip, n=4))
    with open_db(lds_db) as db:
        assert db.texture("waves").read("lds").n == 4
        assert db.texture("waves").source.width == 16


def test_failure_leaves_existing_database_untouched(lds_db):
    data = lds_db.read_bytes()
    clip = load_clip(wave_clip(t=30, h=16, w=16))
    with pytest.raises(RuntimeError, match="boom"):
        with DatabaseWriter(lds_db) as w:
            w.put_texture("waves", clip.source_info())
            raise RuntimeError("boom")
    assert lds_db.read_bytes() == data
    assert _files(lds_db.parent) == ["waves.h5"]


def test_invalid_model_is_not_committed(tmp_path):
    clip = load_clip(wave_clip(t=30, h=16, w=16))
    model = learn_lds(clip, n=4)
    model.A = model.A * 100  # unstable: validation on commit must refuse it
    path = tmp_path / "bad.h5"
    with pytest.raises(TileDBFormatError, match="not stable"):
        with DatabaseWriter(path) as w:
            w.put_texture("t", clip.source_info())
            w.put_method("t", "lds", model)
    assert _files(tmp_path) == []


def test_corrupt_existing_database_is_refused_before_any_work(tmp_path):
    path = tmp_path / "broken.h5"
    path.write_bytes(b"garbage" * 100)
    with pytest.raises(TileDBFormatError):
        DatabaseWriter(path)
    assert path.read_bytes() == b"garbage" * 100
    assert _files(tmp_path) == ["broken.h5"]


def test_remove_texture(lds_db):
    with DatabaseWriter(lds_db) as w:
        w.remove_texture("waves")
    with open_db(lds_db) as db:
        assert db.textures == ()


@pytest.mark.parametrize("name", ["", "a/b", "x" * 65, "../up", " space"])
def test_invalid_texture_names(tmp_path, name):
    clip = load_clip(wave_clip(t=10, h=8, w=8))
    with DatabaseWriter(tmp_path / "n.h5") as w:
        with pytest.raises(ValueError, match="texture name"):
            w.put_texture(name, clip.source_info())
        w.abort()
    assert _files(tmp_path) == []
