"""``WxH`` on the command line, ``(height, width)`` in Python: every size option converts at the edge."""

from __future__ import annotations

import argparse

import cv2
import numpy as np
import pytest

from dynatex.analyzer.quilt import spreading_clip
from dynatex.cli import main
from dynatex.commands._common import size_arg
from dynatex.tiledb import TileDB

from ..conftest import wave_clip


def test_size_arg_reads_width_by_height_and_returns_height_width():
    assert size_arg("40x24") == (24, 40) and size_arg("40X24") == (24, 40)
    for bad in ("40", "40x24x3", "0x24", "40x16385", "ax24"):
        with pytest.raises(argparse.ArgumentTypeError):
            size_arg(bad)


def test_resize_and_size_give_frames_h_high_and_w_wide(tmp_path, capsys):
    np.save(tmp_path / "c.npy", wave_clip(40, 48, 64))
    db = tmp_path / "c.h5"
    assert (
        main(
            [
                "analyze",
                str(tmp_path / "c.npy"),
                "-o",
                str(db),
                "--methods",
                "tiles",
                "--resize",
                "40x24",
                "--tile",
                "12",
                "--tiles-n",
                "2",
                "--tiles-min-loop",
                "12",
            ]
        )
        == 0
    )
    with TileDB(db) as d:
        src = d.texture().source
        assert (src.height, src.width) == (24, 40) and src.source_size == (48, 64)
    assert (
        main(
            [
                "play",
                str(db),
                "--mode",
                "tiles",
                "--size",
                "40x24",
                "--frames",
                "2",
                "--backend",
                "numpy",
                "-o",
                str(tmp_path / "t") + "/",
            ]
        )
        == 0
    )
    frames = sorted((tmp_path / "t").glob("*.png"))
    assert len(frames) == 2 and cv2.imread(str(frames[0])).shape == (24, 40, 3)
    capsys.readouterr()


def test_quilt_size_and_evolve_size(tmp_path, capsys):
    np.save(tmp_path / "s.npy", spreading_clip(12, 32, 32))
    db = tmp_path / "s.h5"
    assert (
        main(
            [
                "analyze",
                str(tmp_path / "s.npy"),
                "-o",
                str(db),
                "--methods",
                "quilt",
                "--quilt-size",
                "40x24",
                "--quilt-block",
                "12",
                "--quilt-rank",
                "4",
            ]
        )
        == 0
    )
    assert "quilt: 40x24 canvas" in capsys.readouterr().err
    with TileDB(db) as d:
        assert d.texture().read("quilt").size == (24, 40)
    assert (
        main(
            [
                "play",
                str(db),
                "--mode",
                "evolve",
                "--size",
                "40x24",
                "--frames",
                "2",
                "--backend",
                "numpy",
                "-o",
                str(tmp_path / "e") + "/",
            ]
        )
        == 0
    )
    frames = sorted((tmp_path / "e").glob("*.png"))
    assert len(frames) == 2 and cv2.imread(str(frames[0])).shape == (24, 40, 3)
    assert (
        main(["play", str(db), "--mode", "evolve", "--size", "24x40", "--frames", "1", "-o", str(tmp_path / "x.png")])
        == 2
    )
    assert "does not fit the stored quilt" in capsys.readouterr().err
