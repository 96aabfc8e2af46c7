"""The ``turnpoints`` group: round trip, validation of damaged or hostile tables, missing tables."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
from dynatex.tiledb import DatabaseWriter, MethodNotFoundError, TileDBFormatError, TurnPointModel, open_db

GROUP = "/textures/pend/turnpoints"


@pytest.fixture(scope="module")
def model_and_clip():
    clip = load_clip(pendulum_clip(80, 24)[0])
    return learn_turnpoints(clip), clip


@pytest.fixture
def db(tmp_path, model_and_clip):
    model, clip = model_and_clip
    path = tmp_path / "tp.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("pend", clip.source_info())
        w.put_frames("pend", clip.frames)
        w.put_method("pend", "turnpoints", model)
    return path


def test_round_trip(db, model_and_clip):
    model = model_and_clip[0]
    with open_db(db) as d:
        tex = d.texture("pend")
        assert "turnpoints" in tex.methods and tex.has_frames
        back = tex.read("turnpoints")
    assert isinstance(back, TurnPointModel)
    for name in ("sym_raw", "symmetry", "reduced", "p_max", "turn_points", "src", "dst", "cost", "future_cost", "prob"):
        assert np.array_equal(getattr(back, name), getattr(model, name)), name
    assert back.exit_frame == model.exit_frame
    assert back.turn_points.dtype == np.int32 and back.prob.dtype == np.float64
    assert back.info["n"] == model.info["n"] and back.info["distance_correlation"] == model.info["distance_correlation"]


def test_database_without_turnpoint_tables(tmp_path, model_and_clip):
    clip = model_and_clip[1]
    path = tmp_path / "bare.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("pend", clip.source_info())
    with open_db(path) as d:
        with pytest.raises(MethodNotFoundError, match=r"no 'turnpoints' data.*--methods turnpoints"):
            d.texture("pend").read("turnpoints")


def _damage(path, name, value=None, *, attr=False, delete=False):
    with h5py.File(path, "a") as f:
        g = f[GROUP]
        if attr:
            g.attrs[name] = value
        elif delete:
            del g[name]
        else:
            del g[name]
            g.create_dataset(name, data=value)


@pytest.mark.parametrize(
    "name, make, match",
    [
        ("turn_points", lambda m: np.array([3, 500], np.int32), r"turn_points: holds indices outside \[0, 80\)"),
        ("turn_points", lambda m: np.array([7], np.int32), "at least 2"),
        ("turn_points", lambda m: m.turn_points[::-1].copy(), "strictly increasing"),
        ("dst", lambda m: np.full(m.dst.shape, -1, np.int32), r"dst: holds indices outside"),
        ("prob", lambda m: m.prob * 3, "outside \\[0, 1\\]"),
        ("symmetry", lambda m: np.full(m.symmetry.shape, np.nan), "NaN"),
        ("p_max", lambda m: m.p_max[:-1], "has shape"),
        ("src", lambda m: m.src.astype(np.float32), "dtype float32 is not integer"),
        ("cost", None, "missing dataset"),
    ],
)
def test_damaged_tables_raise_clear_errors(db, model_and_clip, name, make, match):
    model = model_and_clip[0]
    if make is None:
        _damage(db, name, delete=True)
    else:
        _damage(db, name, make(model))
    with open_db(db) as d:
        with pytest.raises(TileDBFormatError, match=match) as exc:
            d.texture("pend").read("turnpoints")
    assert str(db) in str(exc.value) and GROUP in str(exc.value)


@pytest.mark.parametrize(
    "name, value, match",
    [
        ("n_frames", 81, "differs from the source's 80 frames"),
        ("exit_frame", 80, "out of range"),
        ("exit_frame", 1, "no backward transition|beyond the exit frame"),
        ("n_frames", "eighty", "invalid value"),
    ],
)
def test_damaged_attributes(db, name, value, match):
    _damage(db, name, value, attr=True)
    with open_db(db) as d:
        with pytest.raises(TileDBFormatError, match=match):
            d.texture("pend").read("turnpoints")


def test_writer_validates_before_replacing(db, model_and_clip):
    """A model that fails validation never replaces a good database."""
    model, clip = model_and_clip
    before = db.read_bytes()
    bad = TurnPointModel(**{**model.__dict__, "prob": model.prob + 2.0})
    with pytest.raises(TileDBFormatError, match="prob"):
        with DatabaseWriter(db) as w:
            w.put_method("pend", "turnpoints", bad)
    assert db.read_bytes() == before
