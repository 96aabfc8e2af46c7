"""Hostile values the fuzzer and the issue-16 probe found: every one is a one-line
:class:`TileDBFormatError` naming the file and the object, never a raw exception or garbage."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dynatex.cli import main
from dynatex.tiledb import TileDBFormatError, open_db

from ..conftest import wave_clip


def _set_attr(path, obj, name, value):
    with h5py.File(path, "a") as f:
        f[obj].attrs[name] = value


def _replace(path, dataset, fn):
    with h5py.File(path, "a") as f:
        arr = f[dataset][()]
        del f[dataset]
        f[dataset] = fn(arr)


def _rejected(path, where, match, method="lds"):
    with pytest.raises(TileDBFormatError, match=match) as e, open_db(path) as db:
        db.texture().read(method)
    text = str(e.value)
    assert str(path) in text and where in text and "\n" not in text
    return text


@pytest.mark.parametrize("name", ["crop", "source_size"])
@pytest.mark.parametrize("value", [np.nan, np.inf, "wide", [1.5, 2.0], [1, 2, 3, 4, 5, 6], [-3, 5]])
def test_source_geometry_attributes_are_checked(lds_db, name, value):
    # issue 16, finding 4: NaN/inf/strings raised bare ValueError/OverflowError/TypeError from source.py
    _set_attr(lds_db, "textures/waves/source", name, value)
    with pytest.raises(TileDBFormatError, match=f"/textures/waves/source@{name}") as e:
        open_db(lds_db)
    assert "\n" not in str(e.value)


def test_valid_source_geometry_still_reads(lds_db):
    _set_attr(lds_db, "textures/waves/source", "crop", np.array([2, 3, 32, 24]))
    _set_attr(lds_db, "textures/waves/source", "source_size", np.array([40, 30]))
    with open_db(lds_db) as db:
        s = db.texture().source
    assert s.crop == (2, 3, 32, 24) and s.source_size == (30, 40)  # the file's (w, h), in Python (h, w)


@pytest.mark.parametrize("value", ["1.1", np.array([1.0, np.nan]), np.array([1, 1, 0])])
def test_format_version_must_be_two_integers(lds_db, value):
    _set_attr(lds_db, "/", "format_version", value)
    with pytest.raises(TileDBFormatError, match="/@format_version"):
        open_db(lds_db)


@pytest.mark.parametrize("dataset", ["A", "mean", "x0"])
def test_float16_datasets_are_refused(lds_db, dataset):
    # finding 4: float16 reached numpy's linalg (TypeError) or lost the model's precision
    _replace(lds_db, f"textures/waves/lds/{dataset}", lambda a: a.astype(np.float16))
    _rejected(lds_db, f"/lds/{dataset}", "dtype float16 is not floating point of 32 or 64 bits")


@pytest.fixture
def mixture_db(tmp_path):
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.mixture import learn_mixture
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(wave_clip(t=40, h=16, w=20))
    path = tmp_path / "mix.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("m", clip.source_info())
        w.put_method("m", "mixture", learn_mixture(clip, components=2, dim=3))
    return path


def test_mixture_gauss_cov_float16_is_refused(mixture_db):
    _replace(mixture_db, "textures/m/mixture/gauss_cov", lambda a: a.astype(np.float16))
    _rejected(mixture_db, "/mixture/gauss_cov", "dtype float16", method="mixture")


@pytest.mark.parametrize(
    "dataset, fn, match",
    [
        ("decode_offset", lambda a: np.full_like(a, 1e30), "outside the pixel range"),  # froze the frames (fuzzer)
        ("stacked_basis", lambda a: a * 3, "loading row has norm"),
        ("stacked_basis", lambda a: np.where(np.arange(len(a))[:, None] % 4 == 0, a, 0), "every loading"),
        ("local_radius", lambda a: a * 1e9, "ellipsoid"),
        ("global_coords", lambda a: a * 1e3, "centred with unit covariance"),
        ("ar_intercept", lambda a: a + 1e30, "outside the training coordinates"),
        ("gauss_mean", lambda a: a + 1e30, "outside the training coordinates"),
        ("ar_noise_cov", lambda a: a * 1e12, "total variance"),
    ],
)
def test_mixture_values_outside_the_model_are_refused(mixture_db, dataset, fn, match):
    _replace(mixture_db, f"textures/m/mixture/{dataset}", fn)
    _rejected(mixture_db, f"/mixture/{dataset}", match, method="mixture")


@pytest.mark.parametrize("value", [-1e308, 1e30, 1e5])
def test_initial_state_outside_the_pixel_range_is_refused(lds_db, value):
    # finding 3: x0 = -1e308 passed, overflowed and every frame was black; 1e5 is past the
    # bound for 24x32x3 pixels (256 * sqrt(2304) = 12288) though far from overflowing
    _replace(lds_db, "textures/waves/lds/x0", lambda a: np.full_like(a, value))
    _rejected(lds_db, "/lds/x0", "x0 has norm .* outside the pixel range")


def test_initial_state_play_exits_2_with_one_line(lds_db, tmp_path, capsys):
    _replace(lds_db, "textures/waves/lds/x0", lambda a: np.full_like(a, -1e308))
    code = main(["play", str(lds_db), "--frames", "3", "--backend", "numpy", "-o", str(tmp_path / "x.mp4")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "/lds/x0" in err and len(err.splitlines()) == 1


def test_transient_growth_of_the_expected_state_is_refused(lds_db):
    # x0 inside the bound, but a stable, non-normal A (A^2 = 0) throws it far outside
    with h5py.File(lds_db, "a") as f:
        g = f["textures/waves/lds"]
        n = g["A"].shape[0]
        a = np.zeros((n, n))
        a[0, 1] = 1e6
        x0 = np.zeros(n)
        x0[1] = 100.0
        for name, value in (("A", a), ("x0", x0)):
            del g[name]
            g[name] = value
    text = _rejected(lds_db, "/lds/", "not diagonalisable|x0 has norm|A\\^1 x0")
    assert "/lds/A" in text or "/lds/x0" in text


@pytest.mark.parametrize(
    "fn, where, match",
    [
        (lambda a: np.zeros_like(a), "/lds/basis", "unit length"),
        (lambda a: np.full_like(a, 1e30), "/lds/basis", "unit length"),
        (lambda a: a * 0.5, "/lds/basis", "unit length"),
    ],
)
def test_degenerate_basis_is_refused(lds_db, fn, where, match):
    _replace(lds_db, "textures/waves/lds/basis", fn)
    _rejected(lds_db, where, match)


def test_zero_noise_is_refused(lds_db):
    _replace(lds_db, "textures/waves/lds/B", np.zeros_like)
    _rejected(lds_db, "/lds/B", "without driving noise")


@pytest.mark.parametrize(
    "fn, match",
    [
        (lambda a: a * 3.0, "does not solve P = A P A"),
        (lambda a: -a, "positive semi-definite"),
        (lambda a: np.full_like(a, 1e200), "spread|positive semi-definite"),
    ],
)
def test_stationary_covariance_must_match_the_model(lds_db, fn, match):
    _replace(lds_db, "textures/waves/lds/stationary_cov", fn)
    _rejected(lds_db, "/lds/stationary_cov", match)


def test_defective_transition_matrix_is_refused(lds_db):
    with h5py.File(lds_db, "a") as f:
        g = f["textures/waves/lds"]
        n = g["A"].shape[0]
        a = 0.5 * np.eye(n) + np.eye(n, k=1)  # one Jordan block: eigenvectors all parallel
        del g["A"]
        g["A"] = a
    _rejected(lds_db, "/lds/A", "not diagonalisable")


def test_states_outside_the_pixel_range_are_refused(lds_db):
    _replace(lds_db, "textures/waves/lds/states", lambda a: a * 1e6)
    _rejected(lds_db, "/lds/states", "outside the pixel range")


@pytest.mark.parametrize("value", [-np.inf, np.nan, "wide", 10**6])
def test_tiles_attributes_the_player_uses_are_checked(tmp_path, value):
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.tiles import learn_tiles
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(wave_clip(t=40, h=32, w=32))
    path = tmp_path / "tiles.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "tiles", learn_tiles(clip, tile=12, min_loop=12, transition=4))
    _set_attr(path, "textures/t/tiles", "ring", value)
    _rejected(path, "/tiles@ring", "ring", method="tiles")


@pytest.mark.parametrize("count", [39, 41, 0])
def test_frame_store_must_hold_the_source_frames(tmp_path, count):
    # the fuzzer: a turn-point texture with one stored frame missing passed `info`; numpy raised
    # IndexError and OpenCL read past the frame stack. The count is now checked on open.
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
    from dynatex.player import open_player
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(pendulum_clip(40, 16)[0])
    path = tmp_path / "tp.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
        w.put_method("t", "turnpoints", learn_turnpoints(clip))
    _replace(path, "textures/t/frames", lambda a: np.concatenate([a, a])[:count])
    with pytest.raises(TileDBFormatError, match="/textures/t/frames: holds"):
        open_db(path)
    with pytest.raises(TileDBFormatError, match="/textures/t/frames: holds"):
        open_player(path, mode="turnpoints", backend="numpy")


@pytest.mark.parametrize(
    "value, code",
    [(np.complex128(1 + 2j), 2), (np.array([b"a", b"\xff"]), 0), (b"\xff\xfe", 0), (np.array([[1, 2], [3, 4]]), 0)],
)
def test_reported_attributes_are_plain_values(lds_db, capsys, value, code):
    # `dynatex info --json` died on an attribute it only reports ("Object of type complex is not
    # JSON serializable"); such attributes now reach `info` as plain values, or are refused
    import json

    _set_attr(lds_db, "textures/waves/lds", "svd", value)
    assert main(["info", "--json", str(lds_db)]) == code
    out, err = capsys.readouterr()
    if code:
        assert "/textures/waves/lds@svd: has an unsupported type complex128" in err and len(err.splitlines()) == 1
    else:
        json.loads(out)


@pytest.mark.parametrize("value", [0.0, 255.0])
def test_tile_mean_colours_must_match_the_tiles(tmp_path, value):
    # the value sweep: mean_rgb all 0 (or 255) passed, and the player's colour tone, fitted to
    # those means, turned every frame flat black (or white)
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.tiles import learn_tiles
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(wave_clip(t=40, h=32, w=32))
    path = tmp_path / "tiles.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "tiles", learn_tiles(clip, tile=12, min_loop=12, transition=4))
    _replace(path, "textures/t/tiles/mean_rgb", lambda a: np.full_like(a, value))
    _rejected(path, "/tiles/mean_rgb", "differs from the tiles' own mean colour", method="tiles")
