"""The dynatex command: analyze/info/play end to end, exit codes, one-line errors, no partial files."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import cv2
import h5py
import numpy as np
import pytest

from dynatex.cli import main
from dynatex.tiledb.schema import COMPATIBLE_VERSION, FORMAT_VERSION

from ..conftest import wave_clip


@pytest.fixture
def clip_npy(tmp_path):
    path = tmp_path / "waves.npy"
    np.save(path, wave_clip(t=40, h=24, w=32))
    return path


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    assert lines[0].startswith("dynatex: error: ")
    return lines[0]


def test_analyze_info_play(tmp_path, clip_npy, capsys):
    db = tmp_path / "t.h5"
    code, out, _ = _run(capsys, "analyze", clip_npy, "-o", db, "--n", "8", "-q")
    assert code == 0 and db.exists()
    code, out, _ = _run(capsys, "info", db, "--json")
    info = json.loads(out)
    assert info["textures"]["waves"]["methods"]["lds"]["n"] == 8
    code, out, _ = _run(capsys, "info", db)
    assert code == 0 and "[waves]" in out and "spectral_radius" in out
    video = tmp_path / "o.mp4"
    code, _, _ = _run(capsys, "play", db, "--frames", "12", "--speed", "-1", "--scales", "1,2,0.5", "-o", video)
    assert code == 0
    cap = cv2.VideoCapture(str(video))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == 12
    pngs = tmp_path / "pngs"
    code, _, _ = _run(capsys, "play", db, "--frames", "3", "-o", str(pngs) + os.sep)
    assert code == 0 and sorted(os.listdir(pngs)) == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    assert cv2.imread(str(pngs / "frame_00002.png")).shape == (24, 32, 3)


def test_second_texture_keeps_the_first(tmp_path, clip_npy, capsys):
    db = tmp_path / "t.h5"
    assert _run(capsys, "analyze", clip_npy, "-o", db, "--n", "5", "-q")[0] == 0
    assert _run(capsys, "analyze", clip_npy, "-o", db, "--n", "4", "--name", "other", "-q")[0] == 0
    with h5py.File(db) as f:
        assert sorted(f["textures"]) == ["other", "waves"]


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: d / "missing.avi", "no such clip"),
        (lambda d: _write(d / "empty.avi", b""), "empty"),
        (lambda d: _write(d / "junk.avi", b"\x00junk" * 500), "junk.avi"),
        (lambda d: _npy(d / "one.npy", wave_clip(t=1, h=8, w=8)), "only one frame"),
    ],
)
def test_bad_clips_exit_2_and_leave_no_database(tmp_path, capsys, make, message):
    clip = make(tmp_path)
    before = sorted(os.listdir(tmp_path))
    code, _, err = _run(capsys, "analyze", clip, "-o", tmp_path / "out.h5", "-q")
    assert code == 2
    assert message in _one_line_error(err)
    assert sorted(os.listdir(tmp_path)) == before


def test_n_larger_than_frames_leaves_existing_database_untouched(tmp_path, clip_npy, capsys):
    db = tmp_path / "t.h5"
    assert _run(capsys, "analyze", clip_npy, "-o", db, "--n", "5", "-q")[0] == 0
    data = db.read_bytes()
    code, _, err = _run(capsys, "analyze", clip_npy, "-o", db, "--n", "80", "--name", "x", "-q")
    assert code == 2 and "n=80 is larger than the clip allows" in _one_line_error(err)
    assert db.read_bytes() == data
    assert sorted(os.listdir(tmp_path)) == ["t.h5", "waves.npy"]


def test_corrupt_and_future_databases(tmp_path, clip_npy, capsys):
    db = tmp_path / "t.h5"
    assert _run(capsys, "analyze", clip_npy, "-o", db, "--n", "5", "-q")[0] == 0
    cut = tmp_path / "cut.h5"
    cut.write_bytes(db.read_bytes()[:3000])
    for argv in (("info", cut), ("play", cut, "-o", tmp_path / "x.mp4")):
        code, _, err = _run(capsys, *argv)
        assert code == 2 and "cut.h5" in _one_line_error(err)
    # analyze into a corrupt database refuses before touching it
    code, _, err = _run(capsys, "analyze", clip_npy, "-o", cut, "-q")
    assert code == 2 and cut.stat().st_size == 3000
    with h5py.File(db, "a") as f:
        f.attrs["format_version"] = np.array([9, 0], np.int32)
    code, _, err = _run(capsys, "info", db)
    assert code == 2 and "format version 9.0 is not supported" in _one_line_error(err)
    assert not (tmp_path / "x.mp4").exists()


def test_unknown_texture_and_bad_controls(tmp_path, clip_npy, capsys):
    db = tmp_path / "t.h5"
    assert _run(capsys, "analyze", clip_npy, "-o", db, "--n", "5", "-q")[0] == 0
    out = tmp_path / "o.mp4"
    cases = [
        (("--texture", "fire"), "no texture named 'fire'"),
    ]
    for extra, message in cases:
        code, _, err = _run(capsys, "play", db, "-o", out, *extra)
        assert code == 2 and message in _one_line_error(err)
    for extra, message in [
        (("--intensity", "-1"), "argument --intensity: expected a finite number in [0, 100]"),
        (("--speed", "4"), "argument --speed: expected a finite number in [-3, 3], not '4'"),
        (("--scales", "1,2"), "argument --scales: expected C,M,F: 3 numbers"),
    ]:
        with pytest.raises(SystemExit) as e:
            main(["play", str(db), "-o", str(out), *extra])
        assert e.value.code == 2 and message in capsys.readouterr().err
    assert not out.exists()


def test_usage_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["play"])
    assert e.value.code == 2
    capsys.readouterr()


def test_console_script_runs_without_traceback(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "dynatex", "info", str(tmp_path / "none.h5")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2
    assert r.stderr.strip().startswith("dynatex: error:") and "Traceback" not in r.stderr
    r = subprocess.run(
        [sys.executable, "-m", "dynatex", "--debug", "info", str(tmp_path / "none.h5")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and "Traceback" in r.stderr


def _write(path, data):
    path.write_bytes(data)
    return path


def _npy(path, arr):
    np.save(path, arr)
    return path


def test_analyze_tone_option(tmp_path, capsys):
    """--tone on stores a tone map (format 2.0, shown by info), --tone off none; a bad value is one line."""
    from ..analyzer.test_tone import flames

    clip = tmp_path / "flames.npy"
    np.save(clip, flames(t=40))
    db = tmp_path / "t.h5"
    assert _run(capsys, "analyze", clip, "-o", db, "--n", "6", "-q")[0] == 0
    code, out, _ = _run(capsys, "info", db)
    assert code == 0 and "gaussianised per channel" in out and f"v{FORMAT_VERSION[0]}.{FORMAT_VERSION[1]}" in out
    assert _run(capsys, "analyze", clip, "-o", db, "--n", "6", "--tone", "off", "-q")[0] == 0
    with h5py.File(db) as f:
        assert "tone" not in f["textures/flames/lds"] and tuple(f.attrs["format_version"]) == COMPATIBLE_VERSION
    with pytest.raises(SystemExit) as e:
        main(["analyze", str(clip), "-o", str(db), "--tone", "sometimes", "-q"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and "argument --tone: expected one of 'auto', 'on', 'off'" in err
