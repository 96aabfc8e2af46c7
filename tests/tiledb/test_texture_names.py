"""Texture names in any script: what the format takes, refuses, and how names are looked up."""

from __future__ import annotations

import os
import unicodedata

import h5py
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.tiledb import DatabaseWriter, TileDBFormatError, open_db
from dynatex.tiledb.schema import texture_name_from, texture_name_problem, texture_names_from_paths

from ..conftest import wave_clip

GOOD = ["my clip é", "水", "Wasserfall über Stein", "пламя-2", "a.b_c-d", "x" * 64, "٣ نار"]
BAD = [
    "",
    "a/b",
    "x" * 65,
    ".",
    "..",
    ".hidden",
    " lead",
    "trail ",
    "a\nb",
    "a\tb",
    "nul\x00",
    "a\u2028b",
    "bidi\u202eoverride",
    "private\ue000",
    "e\u0301" + "x" * 64,
]


def _put(db, *names):
    clip = load_clip(wave_clip(t=20, h=8, w=8))
    with DatabaseWriter(db) as w:
        for name in names:
            w.put_texture(name, clip.source_info())
            w.put_method(name, "lds", learn_lds(clip, n=3))


def test_names_in_any_script_round_trip(tmp_path):
    db = tmp_path / "db.h5"
    _put(db, *GOOD)
    with open_db(db) as d:
        assert sorted(d.textures) == sorted(GOOD)
        for name in GOOD:
            assert d.texture(name).read("lds").n == 3
    with h5py.File(db) as f:  # plain UTF-8 link names, as h5dump shows them
        assert "水" in f["textures"]


@pytest.mark.parametrize("name", BAD, ids=[repr(n)[:20] for n in BAD])
def test_names_the_format_refuses(tmp_path, name):
    assert texture_name_problem(name) is not None
    clip = load_clip(wave_clip(t=10, h=8, w=8))
    with DatabaseWriter(tmp_path / "n.h5") as w:
        with pytest.raises(ValueError, match="texture name .* is invalid: it "):
            w.put_texture(name, clip.source_info())
        w.abort()
    assert os.listdir(tmp_path) == []


def test_one_name_however_it_is_spelled(tmp_path):
    db = tmp_path / "db.h5"
    decomposed = unicodedata.normalize("NFD", "café")
    _put(db, decomposed)  # stored in NFC
    with open_db(db) as d:
        assert d.textures == ("café",)
        assert d.texture(decomposed) is d.texture("café")
    with DatabaseWriter(db) as w:  # the writer's lookups normalise too
        w.remove_texture(decomposed)
    with open_db(db) as d:
        assert d.textures == ()


@pytest.mark.parametrize("name", ["bad\nname", ".hidden", "x" * 65, "e\u0301"])
def test_reader_refuses_a_hostile_name(tmp_path, name):
    db = tmp_path / "db.h5"
    _put(db, "ok")
    with h5py.File(db, "a") as f:
        f["textures"].copy("ok", name)
    with pytest.raises(TileDBFormatError, match="invalid texture name"):
        open_db(db)


@pytest.mark.parametrize(
    "stem, name",
    [
        ("my clip é", "my clip é"),
        ("水", "水"),
        (".hidden", "hidden"),
        ("...", "texture"),
        ("", "texture"),
        ("a\nb", "a_b"),
        ("  padded  ", "padded"),
        ("y" * 80, "y" * 64),
        (unicodedata.normalize("NFD", "été"), "été"),
    ],
)
def test_default_names_from_file_names_are_valid(stem, name):
    assert texture_name_from(stem) == name
    assert texture_name_problem(name) is None


def test_names_from_paths_are_distinct_whatever_the_case_and_length():
    long = "z" * 80
    paths = ["a/Fire.avi", "b/fire.mp4", "c/fire_2.avi", f"d/{long}.avi", f"e/{long}.avi", "f/.hidden.npy", "g/ .avi"]
    names = texture_names_from_paths(paths)
    assert names == ["Fire", "fire_2", "fire_2_2", "z" * 64, "z" * 62 + "_2", "hidden", "texture"]
    assert all(texture_name_problem(n) is None for n in names)
    assert len({n.casefold() for n in names}) == len(names)
