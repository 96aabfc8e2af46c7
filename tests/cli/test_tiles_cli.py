"""``dynatex analyze --methods tiles``, ``info`` and ``play --mode tiles`` (mixing, tone, inpainting) end to end."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from dynatex.cli import main

from ..conftest import wave_clip


@pytest.fixture
def clips(tmp_path):
    a, b = tmp_path / "calm.npy", tmp_path / "wild.npy"
    np.save(a, wave_clip(50, 40, 48))
    np.save(b, wave_clip(50, 40, 48, seed=4)[..., ::-1].copy())
    return a, b


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("dynatex: error: ")
    return lines[0]


def test_analyze_info_play_mix_tone_inpaint(tmp_path, clips, capsys):
    db = tmp_path / "t.h5"
    code, _, err = _run(
        capsys,
        "analyze",
        clips[0],
        "-o",
        db,
        "--methods",
        "tiles",
        "--tile",
        "16",
        "--tiles-n",
        "2",
        "--tiles-min-loop",
        "16",
        "--tiles-mix",
        clips[1],
        "--tiles-names",
        "calm,wild",
    )
    assert code == 0, err
    code, out, _ = _run(capsys, "info", db, "--json")
    info = json.loads(out)["textures"]["calm"]["methods"]["tiles"]
    assert info["classes"] == ["calm", "wild"] and info["tile_size"] == "16x16"
    assert info["tiles_per_class"] == [2, 2] and info["border_tiles"] == 8 and info["loop_length"] >= 16
    code, out, _ = _run(capsys, "info", db)
    assert "loop_length" in out and "ring_seam_cost" in out
    png = tmp_path / "f.png"
    code, _, err = _run(
        capsys,
        "play",
        db,
        "--mode",
        "tiles",
        "--size",
        "100x60",
        "--frames",
        "3",
        "-o",
        png,
        "--labels",
        "halves",
        "--tone",
        "consensus",
        "--sigma",
        "8",
        "--max-shift",
        "4",
        "--epoch",
        "20",
    )
    assert code == 0, err
    frame = cv2.imread(str(tmp_path / "f_00002.png"))
    assert frame.shape == (60, 100, 3) and frame.std() > 5
    # inpainting: a video and a mask
    video = tmp_path / "in.avi"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (48, 40))
    for _ in range(4):
        vw.write(np.full((40, 48, 3), 20, np.uint8))
    vw.release()
    mask = np.zeros((40, 48), np.uint8)
    mask[:, 24:] = 255
    cv2.imwrite(str(tmp_path / "mask.png"), mask)
    code, _, err = _run(
        capsys,
        "play",
        db,
        "--mode",
        "tiles",
        "--frames",
        "3",
        "-o",
        tmp_path / "i.png",
        "--inpaint",
        video,
        "--mask",
        tmp_path / "mask.png",
    )
    assert code == 0, err
    f = cv2.imread(str(tmp_path / "i_00000.png")).astype(int)
    assert np.abs(f[:, :20] - 20).max() <= 12 and f[:, 28:].std() > 5  # kept left, synthesized right


def test_bad_input_exits_2_with_one_line(tmp_path, clips, capsys):
    db = tmp_path / "t.h5"
    code, _, err = _run(capsys, "analyze", clips[0], "-o", db, "--methods", "tiles", "--tile", "64")
    assert code == 2 and "larger than the clip frame" in _one_line_error(err)
    assert not db.exists()  # no partial database
    code, _, err = _run(capsys, "analyze", clips[0], "-o", db, "--methods", "tiles", "--tiles-min-loop", "60")
    assert code == 2 and "fewer than the shortest loop" in _one_line_error(err)
    assert not db.exists()
    code, _, err = _run(
        capsys,
        "analyze",
        clips[0],
        "-o",
        db,
        "--methods",
        "tiles",
        "--tile",
        "16",
        "--tiles-min-loop",
        "16",
        "--tiles-construction",
        "ring",
    )  # 16-pixel cells: 3x3 below
    assert code == 0, err
    before = db.read_bytes()
    code, _, err = _run(capsys, "analyze", clips[0], "-o", db, "--name", "x", "--methods", "tiles", "--tile", "64")
    assert code == 2 and db.read_bytes() == before  # the existing database is untouched
    np.save(tmp_path / "lab.npy", np.full((3, 3), 1))
    code, _, err = _run(
        capsys,
        "play",
        db,
        "--mode",
        "tiles",
        "--size",
        "48x48",
        "--frames",
        "1",
        "-o",
        tmp_path / "o.png",
        "--labels",
        tmp_path / "lab.npy",
    )
    assert code == 2 and "labels name texture class 1" in _one_line_error(err)
    code, _, err = _run(
        capsys, "play", db, "--mode", "tiles", "--frames", "1", "-o", tmp_path / "o.png", "--tone", "lava"
    )
    assert code == 2 and "tone names texture 'lava'" in _one_line_error(err)
    np.save(tmp_path / "mask.npy", np.ones((5, 5), np.uint8))
    video = tmp_path / "in.avi"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (48, 40))
    vw.write(np.zeros((40, 48, 3), np.uint8))
    vw.release()
    code, _, err = _run(
        capsys,
        "play",
        db,
        "--mode",
        "tiles",
        "--frames",
        "1",
        "-o",
        tmp_path / "o.png",
        "--inpaint",
        video,
        "--mask",
        tmp_path / "mask.npy",
    )
    assert code == 2 and "mask must have shape (40, 48)" in _one_line_error(err)


def test_quilted_is_the_default_for_one_texture(tmp_path, clips, capsys):
    db = tmp_path / "q.h5"
    code, out, err = _run(
        capsys,
        "analyze",
        clips[0],
        "-o",
        db,
        "--methods",
        "tiles",
        "--tiles-min-loop",
        "16",
        "--tiles-period",
        "144x144",
    )
    assert code == 0, err
    code, out, _ = _run(capsys, "info", db, "--json")
    info = json.loads(out)["textures"]["calm"]["methods"]["tiles"]
    assert info["construction"] == "quilted" and info["torus_rows"] * info["torus_cols"] == info["n_tiles"]
    for side, cell in ((info["period_h"], info["tile_h"]), (info["period_w"], info["tile_w"])):
        assert side % cell == 0 and 144 <= side < 144 + cell  # the asked period, in whole cells
    code, _, err = _run(
        capsys,
        "play",
        db,
        "--mode",
        "tiles",
        "--size",
        "200x120",
        "--frames",
        "2",
        "-o",
        tmp_path / "q.png",
        "--tone",
        "main",
    )
    assert code == 0, err
    assert cv2.imread(str(tmp_path / "q_00001.png")).shape == (120, 200, 3)
    code, _, err = _run(
        capsys, "analyze", clips[0], "-o", tmp_path / "r.h5", "--methods", "tiles", "--tiles-period", "100x3000"
    )
    assert code == 2 and "period must be" in _one_line_error(err)
