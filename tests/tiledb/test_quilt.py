"""The ``quilt`` group: round trip, and every defect of a stored quilt is a clear TileDBFormatError."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.quilt import learn_quilt
from dynatex.tiledb import DatabaseWriter, QuiltModel, TileDBFormatError, open_db
from tests.conftest import wave_clip

from .conftest import edited_copy


@pytest.fixture(scope="module")
def quilt_db(tmp_path_factory):
    clip = load_clip(wave_clip(12, 20, 24))
    model = learn_quilt(clip, size=(30, 40), block=8, rank=5, lowpass=4.0, seed=2)
    path = tmp_path_factory.mktemp("quilt") / "q.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_frames("w", clip.frames)
        w.put_method("w", "quilt", model)
    return path, model


def test_round_trip(quilt_db):
    path, model = quilt_db
    with open_db(path) as db:
        got = db.texture("w").read("quilt")
    assert isinstance(got, QuiltModel)
    for name in (
        "source_map",
        "labels",
        "block_sources",
        "block_positions",
        "singular_values",
        "rank_error",
        "gain",
        "blend_map",
        "blend_labels",
        "blend_weight",
    ):
        np.testing.assert_array_equal(getattr(got, name), getattr(model, name), err_msg=name)
    assert got.size == (30, 40) and got.block == (8, 8) and got.n_blocks == model.n_blocks
    assert got.info["rank"] == 5 and got.info["lowpass"] == 4.0


def _damaged(quilt_db, tmp_path, edit):
    return edited_copy(quilt_db[0], tmp_path, "textures/w/quilt", edit)


def _replace(group, name, data):
    del group[name]
    group.create_dataset(name, data=data)


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda g: _replace(g, "source_map", np.full(g["source_map"].shape, 999, np.int32)),
            "source_map: holds indices",
        ),
        (lambda g: _replace(g, "labels", g["labels"][()] + 10_000), "labels: holds indices"),
        (lambda g: _replace(g, "labels", g["labels"][()][:5]), "labels: has shape"),
        (lambda g: _replace(g, "gain", -g["gain"][()]), "gain: values must lie"),
        (lambda g: _replace(g, "gain", np.full(g["gain"].shape, np.nan, np.float32)), "gain: contains NaN"),
        (lambda g: _replace(g, "rank_error", g["rank_error"][()][::-1]), "rank_error: must lie"),
        (lambda g: _replace(g, "blend_weight", g["blend_weight"][()] + 0.9), "blend_weight: values must lie"),
        (lambda g: g.__delitem__("blend_labels"), "must all be present or all absent"),
        (lambda g: g.attrs.__setitem__("block_h", 500), "does not fit"),
        (lambda g: g.attrs.__setitem__("width", -3), "implausible canvas size"),
    ],
)
def test_damaged_quilt_is_a_format_error(quilt_db, tmp_path, edit, message):
    bad = _damaged(quilt_db, tmp_path, edit)
    with open_db(bad) as db:
        with pytest.raises(TileDBFormatError, match=message) as info:
            db.texture("w").read("quilt")
    assert str(bad) in str(info.value) and "/textures/w/quilt" in str(info.value)


def test_blend_arrays_go_together(tmp_path, quilt_db):
    _, model = quilt_db
    half = QuiltModel(**{**model.__dict__, "blend_labels": None})
    clip = load_clip(wave_clip(12, 20, 24))
    with pytest.raises(ValueError, match="blend_map, blend_labels and blend_weight go together"):
        with DatabaseWriter(tmp_path / "x.h5") as w:
            w.put_texture("w", clip.source_info())
            w.put_method("w", "quilt", half)
    assert not (tmp_path / "x.h5").exists()
