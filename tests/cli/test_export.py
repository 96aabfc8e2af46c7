"""``dynatex export``: flipbook atlases whose grid, order and size match the sidecar, closed loops
for tiles, turnpoints and lds, and the numpy model of the engine's motion-vector blend."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from dynatex.analyzer import flipbook as fb
from dynatex.analyzer import load_clip
from dynatex.analyzer.tiles import learn_tiles
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
from dynatex.cli import main
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip


def _db(path, frames, method, model, *, store: bool = False):
    clip = load_clip(frames)
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        if store:
            w.put_frames("t", clip.frames)
        w.put_method("t", method, model)
    return path


@pytest.fixture(scope="module")
def tiles_db(tmp_path_factory):
    frames = wave_clip(60, 40, 48)
    return _db(tmp_path_factory.mktemp("tiles") / "t.h5", frames, "tiles", learn_tiles(frames, min_loop=16))


@pytest.fixture(scope="module")
def turn_db(tmp_path_factory):
    frames = pendulum_clip(72, 48)[0]
    return _db(
        tmp_path_factory.mktemp("turn") / "p.h5", frames, "turnpoints", learn_turnpoints(load_clip(frames)), store=True
    )


def _read(path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def _export(capsys, *argv) -> tuple[dict, str]:
    assert main(["export", *map(str, argv), "--backend", "numpy"]) == 0
    out = argv[argv.index("-o") + 1]
    (sidecar,) = out.glob("*.json")
    return json.loads(sidecar.read_text()), capsys.readouterr().err


def test_lds_export_matches_its_sidecar_and_the_played_frames(lds_db, tmp_path, capsys):
    out = tmp_path / "fb"
    doc, err = _export(capsys, lds_db, "-o", out, "--mode", "lds", "--frames", "10", "--name", "waves", "--npot")
    assert (doc["cols"], doc["rows"], doc["frames"]) == (3, 4, 10) and "waves_3x4.png" in err
    atlas = _read(out / doc["files"]["color"])
    assert atlas.shape == (doc["atlas_height"], doc["atlas_width"], 3) == (4 * 24, 3 * 32, 3)
    from dynatex.player import open_player

    with open_player(lds_db, mode="lds", backend="numpy", seed=0) as p:
        played = [p.next_frame().copy() for _ in range(10)]
    grid = fb.Grid(3, 4, (24, 32), 10)
    for k in range(12):  # row-major from the top-left, then black cells
        expected = played[k] if k < 10 else np.zeros_like(played[0])
        assert np.array_equal(atlas[grid.cell(k)], expected), k
    mv = _read(out / doc["files"]["motion_vectors"])
    assert mv.shape == atlas.shape and (mv[..., 2] == 0).all()
    assert doc["motion_vectors"]["strength_tile_uv"] > 0 and doc["loop"] == "none"


def test_default_atlas_has_no_empty_cell_and_keeps_the_frame_aspect(lds_db, tmp_path, capsys):
    doc, err = _export(capsys, lds_db, "-o", tmp_path, "--mode", "lds", "--frames", "10", "--no-motion-vectors")
    # 10 frames of 32x24: 2 columns x 5 rows (64x120, within 2:1), not 4x4 with 6 black cells
    assert (doc["cols"], doc["rows"], doc["tile_width"], doc["tile_height"]) == (2, 5, 32, 24)
    assert doc["packing"] == {
        "rule": "packed",
        "cells": 10,
        "empty_cells": 0,
        "empty_share": 0.0,
        "frame_aspect": round(32 / 24, 4),
        "cell_aspect": round(32 / 24, 4),
        "aspect_change": 0.0,
        "cell_scale": [1.0, 1.0],
        "power_of_two": False,
    }
    assert _read(tmp_path / "waves_2x5.png").shape == (120, 64, 3) and "0 empty cells" in err


@pytest.mark.parametrize(
    ("frames", "shape", "grid", "empty"),
    [(80, (288, 352), (8, 10), 0), (79, (288, 352), (8, 10), 1), (7, (64, 64), (4, 2), 1), (1, (9, 700), (1, 1), 0)],
)
def test_packed_grid_wastes_no_cell_it_can_avoid(frames, shape, grid, empty):
    g = fb.choose_grid(frames, shape, packed=True)
    p = fb.packing(g, shape, "packed")
    assert (g.cols, g.rows) == grid and p["empty_cells"] == empty
    assert g.tile == shape and p["aspect_change"] == 0.0
    ah, aw = g.atlas_shape
    assert frames == 1 or max(ah, aw) <= 2 * min(ah, aw)  # never a strip when a 2:1 grid exists


def test_packed_cells_shrink_with_their_aspect_to_fit_the_largest_atlas():
    g = fb.choose_grid(400, (1080, 1920), packed=True)
    assert max(g.atlas_shape) <= fb.MAX_ATLAS_SIDE and g.cols * g.rows == 400
    assert abs(g.tile[1] / g.tile[0] - 1920 / 1080) < 0.01


def test_pow2_atlas_is_a_power_of_two(lds_db, tmp_path, capsys):
    doc, _ = _export(
        capsys, lds_db, "-o", tmp_path, "--mode", "lds", "--frames", "64", "--packing", "pow2", "--no-motion-vectors"
    )
    assert (doc["cols"], doc["rows"], doc["tile_width"], doc["tile_height"]) == (8, 8, 32, 32)
    assert doc["packing"]["power_of_two"] and doc["packing"]["aspect_change"] == round(0.75 - 1, 4)
    assert _read(tmp_path / "waves_8x8.png").shape == (256, 256, 3) and not (tmp_path / "waves_8x8_mv.png").exists()
    assert "motion_vectors" not in doc["files"]


def test_tiles_loop_closes_on_the_tile_loop(tiles_db, tmp_path, capsys):
    doc, _ = _export(capsys, tiles_db, "-o", tmp_path, "--loop", "--npot", "--no-motion-vectors")
    from dynatex.player import open_player

    with open_player(tiles_db, mode="tiles", backend="numpy", seed=0) as p:
        p.epoch = 0
        n = p.loop_length
        frames = [p.next_frame().copy() for _ in range(n + 1)]
    assert doc["frames"] == n and "tile loop" in doc["loop"]
    assert np.array_equal(frames[n], frames[0])  # frame N is frame 0: the loop is closed
    assert doc["wrap_discontinuity"]["ratio"] <= 1.3
    atlas = _read(tmp_path / f"t_{doc['cols']}x{doc['rows']}.png")
    grid = fb.Grid(doc["cols"], doc["rows"], (40, 48), n)
    assert np.array_equal(atlas[grid.cell(n - 1)], frames[n - 1])


def test_turnpoints_loop_is_a_swing_there_and_back(turn_db, tmp_path, capsys):
    doc, _ = _export(capsys, turn_db, "-o", tmp_path, "--mode", "turnpoints", "--loop", "--npot")
    assert "swing between turn points" in doc["loop"] and doc["frames"] % 2 == 0
    ratio = doc["wrap_discontinuity"]["ratio"]
    assert ratio <= 1.3 and doc["wrap_discontinuity"]["reference"] == "median frame step of the source"
    atlas = _read(tmp_path / f"t_{doc['cols']}x{doc['rows']}.png")
    grid = fb.Grid(doc["cols"], doc["rows"], (48, 48), doc["frames"])
    half = doc["frames"] // 2
    assert np.array_equal(atlas[grid.cell(1)], atlas[grid.cell(doc["frames"] - 1)])  # the way back mirrors
    assert not np.array_equal(atlas[grid.cell(0)], atlas[grid.cell(half)])


def test_lds_loop_crossfade_brings_the_wrap_down(lds_db, tmp_path, capsys):
    plain, _ = _export(
        capsys, lds_db, "-o", tmp_path / "a", "--mode", "lds", "--frames", "24", "--npot", "--no-motion-vectors"
    )
    loop, _ = _export(
        capsys,
        lds_db,
        "-o",
        tmp_path / "b",
        "--mode",
        "lds",
        "--frames",
        "24",
        "--npot",
        "--loop",
        "--no-motion-vectors",
    )
    assert "crossfade of the last 6 of 30 frames" in loop["loop"]
    assert loop["wrap_discontinuity"]["ratio"] <= 1.3 < plain["wrap_discontinuity"]["ratio"]


def test_array_layout_is_raw_layers(lds_db, tmp_path, capsys):
    doc, _ = _export(capsys, lds_db, "-o", tmp_path, "--mode", "lds", "--frames", "5", "--npot", "--layout", "array")
    color = np.fromfile(tmp_path / "waves_array_rgba8.raw", np.uint8).reshape(5, 24, 32, 4)
    assert doc["array"]["layers"] == 5 and (color[..., 3] == 255).all()
    assert np.fromfile(tmp_path / "waves_array_rg8.raw", np.uint8).size == 5 * 24 * 32 * 2


@pytest.mark.parametrize(
    "argv, what",
    [
        (["--blend", "3"], "--blend belongs to --loop"),
        (["--loop", "--blend", "64"], "--blend 64 must be fewer"),
        (["--size", "64x64"], "unrecognized arguments: --size 64x64"),
        (["--grid", "2x2", "--frames", "8"], "holds 4 frames"),
    ],
)
def test_bad_export_options_are_one_line(lds_db, tmp_path, capsys, argv, what):
    try:
        code = main(["export", str(lds_db), "-o", str(tmp_path / "x"), "--mode", "lds", "--backend", "numpy", *argv])
    except SystemExit as exc:  # refused by argparse
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert what in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x").exists()


def _moving(n: int, step: float) -> np.ndarray:
    """A smooth random texture translating ``step`` pixels a frame (right and a little down)."""
    rng = np.random.default_rng(1)
    big = cv2.GaussianBlur(rng.integers(0, 256, (160, 400, 3)).astype(np.uint8), (0, 0), 2.5)
    big = cv2.normalize(big, None, 0, 255, cv2.NORM_MINMAX)
    return np.stack(
        [
            cv2.warpAffine(big, np.float32([[1, 0, -i * step], [0, 1, -i * step / 3]]), (400, 160))[40:104, 40:104]
            for i in range(n)
        ]
    )


def test_shader_motion_blend_beats_a_crossfade_on_moving_texture():
    """The numpy model of the engine shader: frame k + 1/2 drawn from the atlas of even frames is
    the true odd frame within a few grey levels, where a crossfade is far off."""
    frames = _moving(33, 2.0)
    even = frames[0::2]
    grid = fb.choose_grid(len(even), even.shape[1:3])
    uv = fb.flow_to_uv(fb.frame_motion(fb.optical_flow(even, wrap=False), wrap=False))
    color = fb.color_atlas(even, grid)
    vectors, strength = fb.vector_atlas(uv, grid)
    inner = (slice(8, -8), slice(8, -8))

    def rms(a, b):
        return float(np.sqrt(np.mean((a[inner].astype(float) - b[inner].astype(float)) ** 2)))

    mv = [rms(fb.shader_blend(color, vectors, grid, strength, k, 0.5), frames[2 * k + 1]) for k in range(1, 14)]
    xf = [rms(fb.crossfade(color, grid, k, 0.5), frames[2 * k + 1]) for k in range(1, 14)]
    assert np.mean(mv) < 2.0 and np.mean(xf) > 6.0, (np.mean(mv), np.mean(xf))
    assert np.array_equal(fb.shader_blend(color, vectors, grid, strength, 3, 0.0), even[3])  # blend 0: frame k


def test_vectors_decode_to_what_was_encoded():
    uv = np.random.default_rng(0).normal(0, 0.01, (3, 4, 5, 2)).astype(np.float32)
    rg, s = fb.encode_vectors(uv, 0.05)
    assert np.abs(fb.decode_vectors(rg, s) - uv).max() <= 0.05 / 255 + 1e-7
    assert fb.encode_vectors(np.zeros((1, 1, 1, 2)), 1.0)[0].tolist() == [[[[128, 128]]]]


@pytest.mark.clips
def test_shader_motion_blend_beats_a_crossfade_on_a_real_clip(clips_dir):
    """The flag clip (benchmarks/flipbook_export.py measures more): a flipbook of every second
    frame, frame k + 1/2 against the true odd frame."""
    frames = load_clip(str(clips_dir / "flag_wind_dyntex_571c110.avi"), stop=33).frames
    even = frames[0::2]
    grid = fb.choose_grid(len(even), even.shape[1:3], pow2=False)
    uv = fb.flow_to_uv(fb.frame_motion(fb.optical_flow(even, wrap=False), wrap=False))
    color = fb.color_atlas(even, grid)
    vectors, strength = fb.vector_atlas(uv, grid)

    def rms(a, b):
        return float(np.sqrt(np.mean((a.astype(float) - b.astype(float)) ** 2)))

    mv = np.array([rms(fb.shader_blend(color, vectors, grid, strength, k, 0.5), frames[2 * k + 1]) for k in range(16)])
    xf = np.array([rms(fb.crossfade(color, grid, k, 0.5), frames[2 * k + 1]) for k in range(16)])
    assert mv.mean() < 0.95 * xf.mean() and (mv < xf).mean() >= 0.75, (mv.mean(), xf.mean())
