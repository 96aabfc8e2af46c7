"""The optional ``turnpoints/flow`` part: round trip, older databases without it, damaged or hostile flows,
and the player drawing a stored pair warped."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
from dynatex.player import open_player
from dynatex.tiledb import DatabaseWriter, TileDBFormatError, open_db
from dynatex.tiledb.turnpoints import FlowModel, flow_grid

FLOW = "/textures/pend/turnpoints/flow"


@pytest.fixture(scope="module")
def model_and_clip():
    clip = load_clip(pendulum_clip(60, 32)[0])
    model = learn_turnpoints(clip, max_ghost=0.0)  # every jump warped: the flows of all are stored
    return model, clip


def _write(path, model, clip):
    with DatabaseWriter(path) as w:
        w.put_texture("pend", clip.source_info())
        w.put_frames("pend", clip.frames)
        w.put_method("pend", "turnpoints", model)
    return path


def test_analysis_stores_the_flows_of_the_jumps(model_and_clip):
    model, clip = model_and_clip
    flow = model.flow
    assert model.src.size and model.info["n_warped"] == model.src.size
    assert flow.step == 4 and flow.flows.shape[1:] == flow_grid(32, 32, 4) + (2,)
    pairs = {tuple(sorted(p)) for p in flow.pairs.tolist()}
    i, j = int(model.src[0]), int(model.dst[0])
    assert (min(i + 1, j), max(i + 1, j)) in pairs  # the first crossfaded pair of the first jump
    assert np.abs(flow.flows).max() > 16  # the pendulum moves more than a pixel between the pair's frames


def test_round_trip_and_the_player_warps(tmp_path, model_and_clip):
    model, clip = model_and_clip
    path = _write(tmp_path / "f.h5", model, clip)
    with open_db(path) as d:
        back = d.texture("pend").read("turnpoints")
    assert back.flow.step == model.flow.step
    assert np.array_equal(back.flow.pairs, model.flow.pairs) and np.array_equal(back.flow.flows, model.flow.flows)
    with open_player(path, mode="turnpoints", playback="jumps", backend="numpy", seed=3) as p:
        for _ in range(400):
            p.next_frame()
        assert p.engine.warped > 0


def test_a_database_without_flows_plays_plain_crossfades(tmp_path, model_and_clip):
    model, clip = model_and_clip
    path = _write(tmp_path / "old.h5", dataclasses.replace(model, flow=None), clip)
    with open_db(path) as d:
        assert d.texture("pend").read("turnpoints").flow is None
    with open_player(path, mode="turnpoints", playback="jumps", backend="numpy", seed=3) as p:
        p.next_frame()
        assert not hasattr(p.engine, "warped")


def test_a_newer_flow_part_is_ignored(tmp_path, model_and_clip):
    path = _write(tmp_path / "new.h5", *model_and_clip)
    with h5py.File(path, "a") as f:
        f[FLOW].attrs["version"] = 2
    with open_db(path) as d:
        assert d.texture("pend").read("turnpoints").flow is None


@pytest.mark.parametrize(
    "damage, match",
    [
        (lambda g: g.attrs.__setitem__("step", 3), "step: 3 is not a power of two"),
        (lambda g: g.attrs.__setitem__("step", 128), "is not a power of two in 1..64"),
        (lambda g: _replace(g, "pairs", np.array(g["pairs"]) + 1000), r"pairs.*out of range|outside"),
        (lambda g: _replace(g, "pairs", np.repeat(np.array(g["pairs"])[:1], 2, axis=0)), "has shape|stored twice"),
        (lambda g: _replace(g, "flows", np.array(g["flows"])[:, :-1]), "has shape"),
        (lambda g: _replace(g, "flows", np.array(g["flows"], np.float32)), "not int16|dtype"),
    ],
    ids=["step-3", "step-128", "pair-range", "pair-twice", "grid-shape", "dtype"],
)
def test_damaged_flows_raise_clear_errors(tmp_path, model_and_clip, damage, match):
    path = _write(tmp_path / "bad.h5", *model_and_clip)
    with h5py.File(path, "a") as f:
        damage(f[FLOW])
    with open_db(path) as d, pytest.raises(TileDBFormatError, match=match):
        d.texture("pend").read("turnpoints")


def test_the_writer_refuses_a_pair_stored_twice(tmp_path, model_and_clip):
    model, clip = model_and_clip
    flow = model.flow
    twice = FlowModel(
        pairs=np.concatenate([flow.pairs, flow.pairs[:1, ::-1]]),
        flows=np.concatenate([flow.flows, flow.flows[:1]]),
        step=flow.step,
    )
    with pytest.raises(TileDBFormatError, match="a pair is stored twice"):  # the writer reads it back first
        _write(tmp_path / "twice.h5", dataclasses.replace(model, flow=twice), clip)


def _replace(group, name, data):
    del group[name]
    group.create_dataset(name, data=data)
