"""``dynatex analyze --methods quilt`` and ``dynatex play --mode evolve`` with a rate map."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dynatex.analyzer.quilt import spreading_clip
from dynatex.cli import main
from dynatex.tiledb import TileDB


@pytest.fixture
def quilt_db(tmp_path, capsys):
    np.save(tmp_path / "s.npy", spreading_clip(16, 32, 32))
    db = tmp_path / "s.h5"
    rc = main(
        [
            "analyze",
            str(tmp_path / "s.npy"),
            "-o",
            str(db),
            "--methods",
            "quilt",
            "--quilt-size",
            "60x40",
            "--quilt-block",
            "12",
            "--quilt-rank",
            "6",
            "--quilt-lowpass",
            "5",
        ]
    )
    assert rc == 0
    assert "quilt: 60x40 canvas from" in capsys.readouterr().err
    return db


def test_analyze_then_play_with_rate_maps(quilt_db, tmp_path):
    with TileDB(quilt_db) as d:
        tex = d.texture("s")
        assert tex.methods == ("quilt",) and tex.has_frames
        assert tex.read("quilt").info["lowpass"] == 5.0
    for i, spec in enumerate(["halves:2,1", "light:30,20,15,2.5,0.5"]):
        out = tmp_path / f"f{i}"
        rc = main(
            [
                "play",
                str(quilt_db),
                "--mode",
                "evolve",
                "--frames",
                "3",
                "--jitter",
                "2",
                "--end",
                "loop",
                "--rate-map",
                spec,
                "--rate-sigma",
                "3",
                "--size",
                "60x40",
                "-o",
                str(out) + "/",
            ]
        )
        assert rc == 0
        pngs = sorted(out.glob("*.png"))
        assert len(pngs) == 3 and cv2.imread(str(pngs[0])).shape == (40, 60, 3)
    img = np.zeros((40, 60), np.uint8)
    img[:, :30] = 255
    cv2.imwrite(str(tmp_path / "m.png"), img)
    rc = main(
        [
            "play",
            str(quilt_db),
            "--mode",
            "evolve",
            "--frames",
            "2",
            "--rate-map",
            str(tmp_path / "m.png"),
            "--rate-range",
            "1,3",
            "-o",
            str(tmp_path / "g") + "/",
        ]
    )
    assert rc == 0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--rate-map", "halves:1"], "needs two rates"),
        (["--rate-map", "halves:-1,2"], "left must be a finite number"),
        (["--rate-map", "nothing.png"], "no such file"),
        (["--size", "64x64"], "does not fit the stored quilt"),
        (["--rate-map", "BAD.npy"], "rate_map is 3x3"),
    ],
)
def test_bad_play_input_is_one_line_and_exit_2(quilt_db, tmp_path, capsys, argv, message):
    np.save(tmp_path / "BAD.npy", np.ones((3, 3)))
    argv = [a.replace("BAD.npy", str(tmp_path / "BAD.npy")) for a in argv]
    capsys.readouterr()
    rc = main(["play", str(quilt_db), "--mode", "evolve", "--frames", "1", *argv, "-o", str(tmp_path / "o") + "/"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_bad_analyze_input_leaves_no_database(tmp_path, capsys):
    np.save(tmp_path / "s.npy", spreading_clip(8, 16, 16))
    db = tmp_path / "s.h5"
    rc = main(["analyze", str(tmp_path / "s.npy"), "-o", str(db), "--methods", "quilt", "--quilt-block", "20"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "block 20x20 (width x height) is larger than the 16x16 source" in err and "\n" not in err
    assert not db.exists()
