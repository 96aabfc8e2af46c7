"""The optional ``gamut`` part of ``lds`` and ``mixture``: what the analysis learns, round trip,
older databases without it, a newer version and grey sources ignored, damaged maps refused."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.gamut import learn_gamut
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.metrics.gamut import colour_bins
from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError
from dynatex.tiledb.gamut import MAX_REGIONS, local_bits

from ..conftest import wave_clip
from .conftest import edited_copy, replace_dataset


def test_the_set_is_the_bins_the_clip_holds_and_each_bin_maps_to_its_nearest(projection_db):
    frames = projection_db.frames
    g = learn_gamut(frames)
    counts = np.bincount(colour_bins(frames), minlength=32**3)
    inside = g.nearest == np.arange(32**3)
    np.testing.assert_array_equal(inside, counts >= 4)
    rgb = lambda b: np.stack([b >> 10, (b >> 5) & 31, b & 31], axis=-1).astype(float)  # noqa: E731
    members = rgb(np.flatnonzero(inside))
    for b in np.random.default_rng(0).integers(0, 32**3, 50):
        best = np.sqrt(((members - rgb(np.array(b))) ** 2).sum(axis=1)).min()
        assert np.sqrt(((rgb(g.nearest[b]) - rgb(np.array(b))) ** 2).sum()) == pytest.approx(best)
    assert learn_gamut(frames[..., :1]) is None  # grey: a projection cannot take a hue


def test_a_clip_of_rare_colours_keeps_its_commonest():
    one = np.zeros((1, 1, 3, 3), np.uint8)
    one[0, 0] = [(0, 0, 0), (100, 0, 0), (0, 0, 200)]
    g = learn_gamut(one)
    assert g.colours == 3  # no bin holds 4 pixels: the set is every bin the clip holds


@pytest.mark.parametrize("method", ["lds", "mixture"])
def test_round_trip(projection_db, method):
    want = projection_db.models[method].gamut
    got = projection_db.read(method).gamut
    np.testing.assert_array_equal(got.nearest, want.nearest)
    assert got.nearest.dtype == np.uint16 and got.info["min_pixels"] == 4
    assert got.colours == want.colours == got.info["colours"]


def _copy(projection_db, tmp_path, edit, method="lds"):
    return edited_copy(projection_db.path, tmp_path, f"textures/w/{method}", edit)


def _read(path, method="lds"):
    with TileDB(path) as t:
        return t.texture("w").read(method)


@pytest.mark.parametrize("method", ["lds", "mixture"])
def test_older_database_reads_without_it(projection_db, tmp_path, method):
    model = _read(_copy(projection_db, tmp_path, lambda g: g.__delitem__("gamut"), method), method)
    assert model.gamut is None and model.detail is not None
    assert model.describe()["gamut"] is False


def test_newer_version_is_ignored(projection_db, tmp_path):
    def newer(g):
        g["gamut"].attrs["version"] = 99

    assert _read(_copy(projection_db, tmp_path, newer)).gamut is None


def test_grey_source_ignores_it(tmp_path):
    # a grey texture written with a colour set (by hand) plays without it
    clip = load_clip(wave_clip(30, h=12, w=16, channels=1), color=False)
    lds = learn_lds(clip, n=3)
    assert lds.gamut is None
    lds.gamut = learn_gamut(wave_clip(30, h=12, w=16))
    grey_db = tmp_path / "grey.h5"
    with DatabaseWriter(grey_db) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", lds)
    assert _read(grey_db).gamut is None


@pytest.mark.parametrize(
    ("fn", "match"),
    [
        (lambda a: a.astype(np.uint32), "not uint16"),
        (lambda a: a.astype(np.int16), "unsigned integer"),
        (lambda a: a[:-1], "expected"),
        (lambda a: np.full_like(a, 40000), "a bin outside 0..32767"),
        (lambda a: np.roll(np.arange(32**3, dtype=np.uint16), 1), "must map to itself"),
        (np.zeros_like, r"holds 1 colours where the part says \d+"),  # every frame would go black
    ],
)
def test_damaged_map_is_refused(projection_db, tmp_path, fn, match):
    with pytest.raises(TileDBFormatError, match=match):
        _read(_copy(projection_db, tmp_path, replace_dataset("gamut/nearest", fn)))


def test_local_sets_round_trip_and_lie_within_the_clip_set(projection_db):
    path, models, frames = projection_db.path, projection_db.models, projection_db.frames
    want = models["lds"].gamut.local
    got = _read(path).gamut.local
    assert got.block == want.block == 16 and got.inside.shape == (2 * 2, 4096)
    np.testing.assert_array_equal(got.inside, want.inside)
    np.testing.assert_array_equal(got.nearest, want.nearest)
    bits = local_bits(got)
    clip_set = models["lds"].gamut.nearest == np.arange(32**3)
    assert not (bits & ~clip_set).any()
    region = (np.arange(20)[:, None] // 16) * 2 + np.arange(28)[None, :] // 16
    held = bits[np.broadcast_to(region, frames.shape[:3]).reshape(-1), colour_bins(frames)]
    assert held.mean() > 0.95  # the clip's own pixels lie in their regions' sets (but lone colours)


def test_older_gamut_reads_without_local_sets(projection_db, tmp_path):
    model = _read(_copy(projection_db, tmp_path, lambda g: g["gamut"].__delitem__("local")))
    assert model.gamut is not None and model.gamut.local is None

    def newer(g):
        g["gamut/local"].attrs["version"] = 99

    assert _read(_copy(projection_db, tmp_path, newer)).gamut.local is None


def _edit_local(name, fn):
    if not name.startswith("@"):
        return replace_dataset(f"gamut/local/{name}", fn)

    def edit(g):
        loc = g["gamut/local"]
        loc.attrs[name[1:]] = fn(loc.attrs[name[1:]])

    return edit


@pytest.mark.parametrize(
    ("name", "fn", "match"),
    [
        ("@block", lambda b: 0, "not a region side"),
        ("@block", lambda b: 1 << 17, "not a region side"),
        ("@block", lambda b: 8, "expected"),  # 3 x 4 regions, not 2 x 2
        ("inside", lambda a: a.astype(np.uint16), "not uint8"),
        ("nearest", lambda a: a[:, :-1], "expected"),
        ("nearest", lambda a: np.full_like(a, 40000), "a bin outside 0..32767"),
        ("nearest", lambda a: (a + 1).astype(np.uint16), "outside its region's set"),
        ("inside", lambda a: np.full_like(a, 255), "outside the clip's colour set"),
    ],
)
def test_damaged_local_sets_are_refused(projection_db, tmp_path, name, fn, match):
    with pytest.raises(TileDBFormatError, match=match):
        _read(_copy(projection_db, tmp_path, _edit_local(name, fn)))


def test_a_frame_smaller_than_a_region_is_one_region(tmp_path):
    clip = load_clip(wave_clip(30, h=8, w=12))
    lds = learn_lds(clip, n=3)
    assert lds.gamut.local.block == 16 and lds.gamut.local.inside.shape == (1, 4096)
    path = tmp_path / "small.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", lds)
    np.testing.assert_array_equal(_read(path).gamut.local.nearest, lds.gamut.local.nearest)


def test_local_sets_stating_more_regions_than_a_reader_lays_out_are_refused(tmp_path):
    """A damaged ``block`` must not make the player lay out per-region and per-quad sets beyond the
    analyzer's bound (the datasets could be stored compressed, far smaller than they unpack)."""
    clip = load_clip(wave_clip(20, h=36, w=36))
    path = tmp_path / "regions.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", learn_lds(clip, n=3))

    def one_pixel_regions(g):
        g["gamut/local"].attrs["block"] = 1  # 1296 regions over 36 x 36

    with pytest.raises(TileDBFormatError, match=f"1296 regions \\(at most {MAX_REGIONS}\\)"):
        _read(edited_copy(path, tmp_path, "textures/w/lds", one_pixel_regions))
