"""The ``tiles`` group: round trip, and damaged or hostile values refused with a clear error."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.tiles import learn_tiles
from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError, TilesModel

from ..conftest import wave_clip
from .conftest import edited_copy, replace_dataset


@pytest.fixture(scope="module")
def model():
    return learn_tiles(
        wave_clip(50, 40, 48),
        tile=16,
        n_tiles=2,
        min_loop=16,
        mix=[wave_clip(50, 40, 48, seed=3)],
        names=["calm", "wild"],
    )


@pytest.fixture(scope="module")
def db_path(tmp_path_factory, model):
    clip = load_clip(wave_clip(50, 40, 48))
    path = tmp_path_factory.mktemp("tiles") / "tiles.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "tiles", model)
    return path


def test_round_trip(db_path, model):
    with TileDB(db_path) as db:
        tex = db.texture("waves")
        assert "tiles" in tex.methods
        back = tex.read("tiles")
    assert isinstance(back, TilesModel)
    for name in (
        "tiles",
        "tile_class",
        "ring_class",
        "masks",
        "border_side",
        "seam_cost",
        "mean_rgb",
        "mean_hsv",
        "class_loop_start",
        "class_loop_cost",
        "class_toroid_cost",
    ):
        assert np.array_equal(getattr(back, name), getattr(model, name)), name
    assert back.class_names == ["calm", "wild"] and back.tiles.dtype == np.uint8
    assert back.loop_length == model.loop_length and back.tile_size == (16, 16)
    assert back.info["ring"] == model.info["ring"]


def _damaged(src, tmp_path, edit):
    return edited_copy(src, tmp_path, "textures/waves/tiles", edit)


def _attr(name, value):
    def edit(g):
        g.attrs[name] = value

    return edit


@pytest.mark.parametrize(
    "edit, match",
    [
        (replace_dataset("tile_class", lambda a: a + 5), r"/tile_class: holds indices outside \[0, 2\)"),
        (replace_dataset("ring_class", lambda a: np.full_like(a, 1)), r"class 0 \('calm'\) has no tile of its own"),
        (replace_dataset("tiles", lambda a: a[:, :, :8]), r"/tiles: has shape"),
        (replace_dataset("tiles", lambda a: a.astype(np.float32)), r"/tiles: dtype float32 is not unsigned integer"),
        (replace_dataset("mean_rgb", lambda a: a * np.nan), r"/mean_rgb: contains NaN"),
        (replace_dataset("border_side", lambda a: np.full_like(a, -1)), r"/border_side: must be 0..3 for border tiles"),
        (_attr("loop_length", 1), r"@loop_length: loop length 1 outside"),
        (_attr("n_tiles", 10**6), r"@n_tiles"),
        (lambda g: g.__delitem__("masks"), r"/masks: missing dataset"),
        (
            replace_dataset("edges", lambda a: np.full_like(a, 1)),
            r"/edges: tiles have edge colours but construction is 'ring'",
        ),
        (
            lambda g: (replace_dataset("edges", lambda a: np.full_like(a, 1))(g), _attr("construction", "wang")(g)),
            r"/edges: a Wang set must be every tile of a single class",
        ),
        (replace_dataset("edges", lambda a: np.full((len(a), 3), -1, np.int8)), r"/edges: has shape"),
    ],
)
def test_damaged_group_is_refused(db_path, tmp_path, edit, match):
    path = _damaged(db_path, tmp_path, edit)
    with TileDB(path) as db:
        with pytest.raises(TileDBFormatError, match=match):
            db.texture("waves").read("tiles")


@pytest.fixture(scope="module")
def wang_path(tmp_path_factory):
    frames = wave_clip(50, 40, 48)
    model = learn_tiles(frames, tile=16, construction="wang", min_loop=16)
    path = tmp_path_factory.mktemp("wang") / "wang.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("waves", load_clip(frames).source_info())
        w.put_method("waves", "tiles", model)
    return path, model


def test_wang_round_trip_and_a_ring_set_has_no_colours(wang_path, db_path):
    path, model = wang_path
    with TileDB(path) as db:
        back = db.texture("waves").read("tiles")
    assert back.wang and np.array_equal(back.edges, model.edges) and back.info["construction"] == "wang"
    assert back.info["edge_colours"] == 2 and back.n_tiles == 8
    with TileDB(db_path) as db:
        ring = db.texture("waves").read("tiles")
    assert not ring.wang and (ring.edges == -1).all()


def test_tile_set_without_edges_reads_as_ring(db_path, tmp_path):
    """A format 1.0 file has no ``edges``: every tile is outside any Wang set."""
    path = _damaged(db_path, tmp_path, lambda g: g.__delitem__("edges"))
    with TileDB(path) as db:
        back = db.texture("waves").read("tiles")
    assert not back.wang and back.edges.shape == (back.n_tiles, 4)


@pytest.mark.parametrize(
    "edit, match",
    [
        (
            replace_dataset("edges", lambda a: np.where(np.arange(4) == 0, -1, a).astype(np.int8)),
            "some edges and -1 on others",
        ),
        (
            replace_dataset("edges", lambda a: np.stack([a[:, 0], 1 - a[:, 1], a[:, 2], a[:, 3]], 1)),
            "one tile per \\(left, top, bottom\\)",
        ),
        (replace_dataset("edges", lambda a: np.concatenate([a[:1], a[:-1]])), "one tile per \\(left, top, bottom\\)"),
        (replace_dataset("edges", lambda a: a.astype(np.int32) + 256), "values must be -1 or edge colours 0..7"),
        (lambda g: g.__delitem__("edges"), "construction is 'wang' but no tile has edge colours"),
        (_attr("construction", "ring"), "tiles have edge colours but construction is 'ring'"),
        (_attr("construction", "hex"), "@construction: must be one of"),
        (_attr("edge_colours", 3), "@edge_colours: says 3 but the edges use 2 colours"),
        (_attr("strip_depth", 99), "@strip_depth: 99 outside"),
    ],
)
def test_damaged_wang_edges_are_refused(wang_path, tmp_path, edit, match):
    path = _damaged(wang_path[0], tmp_path, edit)
    with TileDB(path) as db:
        with pytest.raises(TileDBFormatError, match=match):
            db.texture("waves").read("tiles")


def test_the_most_tile_classes_fit_the_tone_table():
    """Each class's tone and two blend levels for every pair of classes (the fewest a feathered
    border gets) fit the player's tone table, whose size the format states."""
    from dynatex.tiledb.tiles import MAX_CLASSES, MAX_TONES

    assert MAX_TONES == 256  # a tone index is 8 bits of a packed source entry
    assert MAX_CLASSES + 2 * MAX_CLASSES**2 <= MAX_TONES
