"""``dynatex analyze --methods turnpoints`` and ``dynatex play --mode turnpoints`` end to end."""

from __future__ import annotations

import os

import cv2
import h5py
import numpy as np
import pytest

from dynatex.analyzer.turnpoints import pendulum_clip
from dynatex.cli import main

from ..conftest import opencl_backends


@pytest.fixture
def clip_npy(tmp_path):
    path = tmp_path / "pend.npy"
    np.save(path, pendulum_clip(70, 32)[0])
    return path


def _run(capsys, *argv):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # a usage error argparse reports (exit code 2)
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_analyze_plot_and_play(tmp_path, clip_npy, capsys):
    db, png = tmp_path / "p.h5", tmp_path / "sym.png"
    code, _, err = _run(
        capsys, "analyze", clip_npy, "-o", db, "--methods", "turnpoints", "--tp-n", "3", "--tp-plot", png
    )
    assert code == 0, err
    assert "turn points" in err and png.stat().st_size > 5000
    with h5py.File(db) as f:
        g = f["textures/pend"]
        assert "turnpoints" in g and g["frames"].shape == (70, 32, 32, 3)
        assert g["turnpoints"].attrs["n"] == 3
    for backend in opencl_backends():
        out = tmp_path / backend
        code, _, err = _run(
            capsys,
            "play",
            db,
            "--mode",
            "turnpoints",
            "--frames",
            "6",
            "--speed",
            "0.5",
            "--playback",
            "turns",
            "--backend",
            backend,
            "-o",
            str(out) + os.sep,
        )
        assert code == 0, err
        assert len(os.listdir(out)) == 6
    a = cv2.imread(str(tmp_path / "numpy" / "frame_00005.png"))
    assert a.shape == (32, 32, 3)
    if "opencl" in opencl_backends():
        assert np.array_equal(a, cv2.imread(str(tmp_path / "opencl" / "frame_00005.png")))
    video = tmp_path / "o.mp4"
    code, _, _ = _run(capsys, "play", db, "--mode", "turnpoints", "--frames", "30", "--crossfade", "2", "-o", video)
    assert code == 0 and video.stat().st_size > 0


def test_bad_parameters_leave_existing_database_untouched(tmp_path, clip_npy, capsys):
    db = tmp_path / "p.h5"
    assert _run(capsys, "analyze", clip_npy, "-o", db, "-q")[0] == 0  # lds only
    data = db.read_bytes()
    cases = [
        (("--tp-n", "40"), "too short for n=40"),
        (("--tp-s", "2"), "s must satisfy"),
        (("--tp-min-symmetry", "1.5"), "argument --tp-min-symmetry: expected a finite number in [0, 1)"),
    ]
    for extra, message in cases:
        code, _, err = _run(
            capsys, "analyze", clip_npy, "-o", db, "--methods", "turnpoints", "--name", "x", "-q", *extra
        )
        assert code == 2 and message in _one_line_error(err)
        assert db.read_bytes() == data
    assert sorted(os.listdir(tmp_path)) == ["p.h5", "pend.npy"]
    # a database without turn-point tables
    code, _, err = _run(capsys, "play", db, "--mode", "turnpoints", "-o", tmp_path / "o.mp4")
    assert code == 2 and "no 'turnpoints' data" in _one_line_error(err)
    assert not (tmp_path / "o.mp4").exists()


def test_bad_controls(tmp_path, clip_npy, capsys):
    db = tmp_path / "p.h5"
    assert _run(capsys, "analyze", clip_npy, "-o", db, "--methods", "turnpoints", "-q")[0] == 0
    for extra, message in [
        (("--speed", "5"), "argument --speed: expected a finite number in [0, 4], not '5'"),
        (("--crossfade", "30"), "--crossfade: expected an integer in 0..16"),
        (("--size", "64x64"), "unrecognized arguments: --size 64x64"),
        (("--start", "500"), "start must be"),
    ]:
        code, _, err = _run(capsys, "play", db, "--mode", "turnpoints", "-o", tmp_path / "o.mp4", *extra)
        assert code == 2 and message in _one_line_error(err)
    assert not (tmp_path / "o.mp4").exists()
