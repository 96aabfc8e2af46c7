"""``--methods auto``: which methods suit a clip, learning that survives a method's failure, the ranking."""

from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.auto import MODE_OF, choose_methods, learn_chosen, rank, time_trend
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.turnpoints import pendulum_clip
from dynatex.cli import main
from dynatex.errors import DynatexError
from dynatex.player import MODES
from dynatex.tiledb import DatabaseWriter, open_db
from dynatex.tiledb.errors import TileDBError

from ..conftest import wave_clip


def _chosen(frames: np.ndarray) -> dict[str, bool]:
    return {c.method: c.chosen for c in choose_methods(frames)}


def test_every_method_has_a_mode():
    assert set(MODE_OF.values()) <= set(MODES)
    assert {c.method for c in choose_methods(wave_clip(t=30))} == set(MODE_OF)


def test_a_stationary_texture_gets_the_stationary_methods():
    waves = wave_clip(t=60, h=48, w=64)
    assert time_trend(waves) < 0.2
    assert _chosen(waves) == {"lds": True, "mixture": True, "turnpoints": True, "tiles": True, "quilt": False}


def test_a_drifting_clip_gets_the_quilt_and_not_the_mixture():
    waves = wave_clip(t=60, h=48, w=64).astype(float)
    ramp = np.linspace(0, 1, 60)[:, None, None, None]
    rusting = (waves * (1 - 0.8 * ramp) + 200 * ramp * np.array([1.0, 0.5, 0.2])).clip(0, 255).astype(np.uint8)
    assert time_trend(rusting) > 0.5
    chosen = _chosen(rusting)
    assert chosen["quilt"] and not chosen["mixture"] and chosen["lds"]


def test_an_object_on_a_background_gets_no_tiles():
    frames, _ = pendulum_clip(60, 48)
    chosen = _chosen(frames)
    assert not chosen["tiles"] and chosen["turnpoints"]


def test_a_method_that_cannot_learn_is_left_out(tmp_path):
    clip = load_clip(wave_clip(t=16, h=24, w=32))  # too few frames for 3 mixture components of dim 10
    with DatabaseWriter(tmp_path / "a.h5") as w:
        learned, failed = learn_chosen(w, "a", clip, ["lds", "mixture"], params={"lds": {"n": 8}})
    assert learned == ["lds"] and "mixture" in failed and failed["mixture"]
    with open_db(tmp_path / "a.h5") as db:
        assert db.texture("a").methods == ("lds",)


def test_rank_orders_by_verdicts(tmp_path):
    clip = load_clip(pendulum_clip(90, 32)[0])
    path = tmp_path / "r.h5"
    with DatabaseWriter(path) as w:
        learned, _ = learn_chosen(w, "r", clip, ["lds", "turnpoints"], params={"lds": {"n": 10}})
    assert learned == ["lds", "turnpoints"]
    ranking = rank(path, "r", clip.frames, ["lds", "turnpoints"], frames=60)
    assert [e["rank"] for e in ranking] == [1, 2]
    assert {e["mode"] for e in ranking} == {"lds", "turnpoints"}
    assert ranking[0]["score"] <= ranking[1]["score"]
    for e in ranking:
        assert e["verdict"] in ("good", "poor", "bad") and e["why"]
        assert all(v in ("good", "poor", "bad") for _, v in e["figures"].values())
    json.dumps(ranking, allow_nan=False)  # storable


def test_writer_stores_default_mode_and_ranking_and_info_shows_them(tmp_path, capsys):
    clip = load_clip(wave_clip(t=30))
    path = tmp_path / "d.h5"
    ranking = [{"mode": "lds", "rank": 1, "verdict": "good", "score": 0.0, "why": "all 5 judged figures good"}]
    with DatabaseWriter(path) as w:
        w.put_texture("d", clip.source_info())
        w.put_method("d", "lds", learn_lds(clip.frames, n=4))  # a default mode names a method the texture holds
        w.put_default_mode("d", "lds", ranking)
        with pytest.raises(DynatexError, match="mode name"):
            w.put_default_mode("d", "Not A Mode!")
    with h5py.File(path, "r") as f:
        assert f["textures/d"].attrs["default_mode"] == "lds"
    with open_db(path) as db:
        assert db.texture("d").ranking == ranking
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"1\. lds +good +all 5 judged figures good \(default mode\)", out), out
    # a later write of another texture keeps both attributes
    with DatabaseWriter(path) as w:
        w.put_texture("e", clip.source_info())
    with open_db(path) as db:
        assert db.texture("d").ranking == ranking and db.texture("e").ranking is None


def test_a_damaged_ranking_is_a_format_error(tmp_path):
    clip = load_clip(wave_clip(t=30))
    path = tmp_path / "x.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("x", clip.source_info())
    with h5py.File(path, "r+") as f:
        f["textures/x"].attrs["ranking"] = "{not json"
    with open_db(path) as db, pytest.raises(TileDBError, match="ranking"):
        db.texture("x").ranking  # noqa: B018


def test_cli_auto_ranks_and_marks_the_default(tmp_path, capsys):
    np.save(tmp_path / "w.npy", wave_clip(t=40, h=32, w=32))
    db = tmp_path / "w.h5"
    rc = main(
        ["analyze", str(tmp_path / "w.npy"), "-o", str(db), "--methods", "auto", "--auto-frames", "40", "--n", "8"]
    )
    assert rc == 0
    err = capsys.readouterr().err
    assert "auto: quilt: no: no trend over time" in err and "(default mode)" in err
    with h5py.File(db, "r") as f:
        default = f["textures/w"].attrs["default_mode"]
    with open_db(db) as d:
        ranking = d.texture("w").ranking
        methods = d.texture("w").methods
    assert ranking[0]["mode"] == default and default in MODES
    assert sorted(e["mode"] for e in ranking) == sorted(MODE_OF[m] for m in methods)
    assert main(["analyze", str(tmp_path / "w.npy"), "-o", str(db), "--methods", "auto,lds"]) == 2
    assert "name no other method" in capsys.readouterr().err
