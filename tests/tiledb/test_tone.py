"""The required ``tone`` part of ``lds`` and ``mixture``: round trip, the format version it takes
(2.x with it, 1.x without), damaged and newer maps refused, and the range checks it relaxes."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError, TileDBVersionError, ToneModel
from dynatex.tiledb.schema import COMPATIBLE_VERSION, FORMAT_VERSION
from dynatex.tiledb.tone import BINS, LEVELS, forward_problem, lookup

from .conftest import edited_copy, replace_dataset
from .test_format_doc import FORMAT_MD, _sections

METHODS = ("lds", "mixture")


def forward_table(channels: int = 3, low: float = -60.0, scale: float = 1.2) -> np.ndarray:
    """A valid map: steep where levels are rare (the ends), a tail below 0, a channel apart from the next."""
    levels = np.arange(LEVELS, dtype=np.float64)
    rows = [low + 3 * c + scale * levels + 25 * np.tanh((levels - 128) / 30) for c in range(channels)]
    return np.stack(rows).astype(np.float32)


def _with_tone(model, forward=None, **changes):
    tone = ToneModel(forward=forward_table() if forward is None else forward, info={"saturation_share": 0.153})
    return dataclasses.replace(model, tone=tone, **changes)


def _write(path, projection_db, models: dict) -> None:
    """A database of texture ``w`` (the projection database's source) holding ``models``."""
    with DatabaseWriter(path) as w:
        w.put_texture("w", _source(projection_db))
        for method, model in models.items():
            w.put_method("w", method, model)


def _source(projection_db):
    with TileDB(projection_db.path) as t:
        return t.texture("w").source


@pytest.fixture(scope="module")
def tone_db(projection_db, tmp_path_factory):
    """The projection database's models, both with a tone map."""
    path = tmp_path_factory.mktemp("tone") / "tone.h5"
    _write(path, projection_db, {m: _with_tone(projection_db.models[m]) for m in METHODS})
    return path


def _version(path) -> tuple[int, int]:
    with h5py.File(path, "r") as f:
        return tuple(int(v) for v in f.attrs["format_version"])


def _read(path, method):
    with TileDB(path) as t:
        return t.texture("w").read(method)


@pytest.mark.parametrize("method", METHODS)
def test_round_trip(tone_db, method):
    got = _read(tone_db, method)
    np.testing.assert_array_equal(got.tone.forward, forward_table())
    assert got.tone.forward.dtype == np.float32 and got.tone.channels == 3
    assert got.tone.info == {"saturation_share": pytest.approx(0.153)}
    facts = got.describe()
    assert facts["tone"] == "gaussianised per channel" and facts["tone_saturation_share"] == 0.153


@pytest.mark.parametrize("method", METHODS)
def test_a_model_without_tone_reads_as_before(projection_db, method):
    model = projection_db.read(method)
    assert model.tone is None and "tone" not in model.describe()


def test_the_file_is_2_x_with_a_tone_part_and_1_x_without(projection_db, tone_db, tmp_path):
    assert COMPATIBLE_VERSION[0] == 1 and FORMAT_VERSION[0] == 2
    assert _version(projection_db.path) == COMPATIBLE_VERSION
    assert _version(tone_db) == FORMAT_VERSION
    with TileDB(tone_db) as t:
        assert t.version == FORMAT_VERSION
    # a texture without tone added to the file: the carried texture keeps it 2.x
    path = tmp_path / "db.h5"
    path.write_bytes(tone_db.read_bytes())
    with DatabaseWriter(path) as w:
        w.put_texture("plain", _source(projection_db))
        w.put_method("plain", "lds", projection_db.models["lds"])
    assert _version(path) == FORMAT_VERSION
    # the tone models replaced by models without: back to 1.x, which 1.x readers read
    with DatabaseWriter(path) as w:
        for method in METHODS:
            w.put_method("w", method, projection_db.models[method])
    assert _version(path) == COMPATIBLE_VERSION
    # one tone model on the other texture: 2.x again; that texture removed: 1.x
    with DatabaseWriter(path) as w:
        w.put_method("plain", "mixture", _with_tone(projection_db.models["mixture"]))
    assert _version(path) == FORMAT_VERSION
    with DatabaseWriter(path) as w:
        w.remove_texture("plain")
    assert _version(path) == COMPATIBLE_VERSION
    with TileDB(path) as t:
        assert t.textures == ("w",) and t.texture("w").read("lds").tone is None


def test_a_1_x_file_holding_a_tone_part_is_refused(tone_db, tmp_path):
    # what an older reader would play without its map: a file written so is damaged
    path = tmp_path / "old.h5"
    path.write_bytes(tone_db.read_bytes())
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = np.array([1, 7], np.int32)
    with pytest.raises(TileDBFormatError, match="/textures/w/lds/tone: a format 1.7 file cannot hold") as e:
        TileDB(path)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("major", [0, 3, 9])
def test_other_majors_are_refused(tone_db, tmp_path, major):
    path = tmp_path / "future.h5"
    path.write_bytes(tone_db.read_bytes())
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = np.array([major, 0], np.int32)
    with pytest.raises(TileDBVersionError, match=f"format version {major}.0 is not supported.*major versions 1-2"):
        TileDB(path)


def _copy(path, tmp_path, edit, method="lds"):
    return edited_copy(path, tmp_path, f"textures/w/{method}/tone", edit)


def _refused(path, method, match, error=TileDBFormatError, where="/tone/forward"):
    with pytest.raises(error, match=match) as e:
        _read(path, method)
    text = str(e.value)
    assert str(path) in text and f"/textures/w/{method}{where}" in text and "\n" not in text
    return text


def _set(index, value):
    def fn(a):
        a = a.copy()
        a[index] = value
        return a

    return fn


def _step_below_a_bin(a):
    a = a.copy()
    a[0, 50] = a[0, 49] + 0.2 * (a[0, 255] - a[0, 0]) / BINS
    return a


HOSTILE = [
    ("two channels", lambda a: a[:2], r"has shape \(2, 256\), expected \(3, 256\)"),
    ("255 levels", lambda a: a[:, :255], r"has shape \(3, 255\), expected \(3, 256\)"),
    ("float64", lambda a: a.astype(np.float64), "dtype float64 is not float32"),
    ("integers", lambda a: a.astype(np.int32), "dtype int32 is not floating point"),
    ("NaN", _set((1, 7), np.nan), "NaN or infinite"),
    ("infinite", _set((2, 255), np.inf), "NaN or infinite"),
    ("flat", lambda a: _set((1, 100), a[1, 99])(a), "not strictly increasing"),
    ("decreasing", lambda a: a[:, ::-1].copy(), "not strictly increasing"),
    ("step below a bin", _step_below_a_bin, "channel 0 has a step of .* below its span over 4096 bins"),
    ("huge top", _set((2, 255), 1e6), "values reach 1e\\+06, beyond \\+-10000"),
    ("huge everywhere", lambda a: (a.astype(np.float64) * 1e36).astype(np.float32), "beyond \\+-10000"),
    # steps a bin wide, but BINS / span overflows float32: the lookup's scale would be infinite
    ("tiny span", lambda a: (np.arange(256) * 1e-38)[None].repeat(3, 0).astype(np.float32), "spans .* under 1"),
]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(("what", "fn", "match"), HOSTILE, ids=[h[0] for h in HOSTILE])
def test_a_damaged_map_is_refused(tone_db, tmp_path, method, what, fn, match):
    _refused(_copy(tone_db, tmp_path, replace_dataset("forward", fn), method), method, match)


def test_a_missing_map_is_refused(tone_db, tmp_path):
    _refused(_copy(tone_db, tmp_path, lambda g: g.__delitem__("forward")), "lds", "missing dataset")


@pytest.mark.parametrize("method", METHODS)
def test_a_newer_tone_version_is_refused_not_ignored(tone_db, tmp_path, method):
    def newer(g):
        g.attrs["version"] = 2

    text = _refused(_copy(tone_db, tmp_path, newer, method), method, "upgrade dynatex", TileDBVersionError, "/tone")
    assert f"the {method} model of texture 'w' needs its tone part, of version 2" in text


@pytest.mark.parametrize("value", [0, -1, "1", 1.5])
def test_the_version_must_be_a_positive_integer(tone_db, tmp_path, value):
    def bad(g):
        g.attrs["version"] = value

    _refused(_copy(tone_db, tmp_path, bad), "lds", "@version", where="/tone@version")


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("value", ["", "0.2", [0.1, 0.2]])
def test_the_saturation_share_must_be_a_number(tone_db, tmp_path, method, value):
    """``dynatex info`` shows it as a number (a fuzzed ``""`` raised ValueError there)."""

    def bad(g):
        g.attrs["saturation_share"] = value

    _refused(_copy(tone_db, tmp_path, bad, method), method, "saturation_share", where="/tone@saturation_share")


def test_each_other_part_of_the_model_still_reads_with_tone(tone_db):
    model = _read(tone_db, "mixture")
    assert model.detail is not None and model.gamut is not None and model.switching is not None


@pytest.mark.parametrize("method", METHODS)
def test_a_mean_below_0_is_accepted_within_the_tone_range_only(projection_db, tmp_path, method):
    model = projection_db.models[method]
    mean = (model.mean - model.mean.min() - 20).astype(np.float32)  # down to -20; the map reaches -85
    path = tmp_path / "low.h5"
    _write(path, projection_db, {method: _with_tone(model, mean=mean)})
    assert _read(path, method).mean.min() == pytest.approx(-20)
    without = edited_copy(path, tmp_path, f"textures/w/{method}", lambda g: g.__delitem__("tone"))
    _refused(without, method, "values outside the 0..255 pixel range", where="/mean")
    below = edited_copy(path, tmp_path, f"textures/w/{method}", replace_dataset("mean", lambda a: a - 80))
    _refused(below, method, r"values outside the tone map's range \(-8\d\.\d+\.\.", where="/mean")


def _wide(model, method, p: int):
    """``model`` with a state (lds) or a decoded offset (mixture) of norm ``300 sqrt(P)``: past the pixel
    range's bound, within a tone map's of span 410."""
    size = 300 * np.sqrt(p)
    if method == "lds":
        states = model.states.copy()
        states[:, 0] *= size / np.sqrt(states[:, 0] @ states[:, 0])
        return {"states": states}
    offset = model.decode_offset.copy()
    offset[0] *= size / np.sqrt(offset[0] @ offset[0])
    return {"decode_offset": offset}


@pytest.mark.parametrize("method", METHODS)
def test_the_state_bounds_follow_the_tone_range(projection_db, tmp_path, method):
    model = projection_db.models[method]
    wide = forward_table(low=-150.0, scale=1.6)  # span about 460
    path = tmp_path / "wide.h5"
    changes = _wide(model, method, projection_db.frames[0].size)
    _write(path, projection_db, {method: _with_tone(model, forward=wide, **changes)})
    assert _read(path, method).tone is not None
    without = edited_copy(path, tmp_path, f"textures/w/{method}", lambda g: g.__delitem__("tone"))
    where = "/states" if method == "lds" else "/decode_offset"
    _refused(without, method, "outside the pixel range", where=where)


@pytest.mark.parametrize("method", METHODS)
def test_the_format_documents_what_is_written(tone_db, method):
    doc = _sections()["tone"]
    with h5py.File(tone_db, "r") as f:
        g = f[f"textures/w/{method}/tone"]
        assert set(g.attrs) <= set(doc["attributes"]) and set(g) == set(doc["datasets"]) == {"forward"}
        assert doc["datasets"]["forward"] == "float32" == g["forward"].dtype
    assert f"`BINS = {BINS}`" in FORMAT_MD.read_text(encoding="utf-8")


def test_the_rule_names_each_defect():
    assert forward_problem(forward_table()) is None
    a = forward_table()
    assert "channel 0, levels 3 -> 4" in forward_problem(_set((0, 4), a[0, 3] - 1)(a))


def test_the_lookup_is_within_one_level_of_the_nearest_level():
    tone = ToneModel(forward=forward_table())
    table = lookup(tone)
    assert table.shape == (3, BINS) and table.dtype == np.uint8
    f = tone.forward.astype(np.float64)
    span = f[:, -1] - f[:, 0]
    for c in range(3):
        assert table[c, 0] == 0 and table[c, -1] == 255
        assert (np.diff(table[c].astype(int)) >= 0).all() and len(np.unique(table[c])) == LEVELS  # every level shows
        centres = f[c, 0] + (np.arange(BINS) + 0.5) * span[c] / BINS
        nearest = np.abs(centres[:, None] - f[c][None, :]).argmin(axis=1)
        np.testing.assert_array_equal(table[c], nearest)
        # any value, not only a bin's centre: the bin's level is within one level of its nearest
        y = np.random.default_rng(c).uniform(f[c, 0] - 5, f[c, -1] + 5, 20000)
        bins = np.clip(np.floor((y - f[c, 0]) * BINS / span[c]), 0, BINS - 1).astype(int)
        exact = np.abs(y[:, None] - f[c][None, :]).argmin(axis=1)
        assert np.abs(table[c, bins].astype(int) - exact).max() <= 1
