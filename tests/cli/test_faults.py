"""Faults around a running command end cleanly: a full disk during analysis, merge or output is
one line and exit 2 with nothing left behind (and no crash in HDF5 at exit); SIGTERM ends a run
like Ctrl-C, removing its decode folder, spill file and temporary database; scratch space that
a killed run left is removed by the next run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from dynatex.analyzer.video import remove_stale_scratch
from dynatex.stale import hold, release

from ..conftest import wave_clip

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _dynatex(*argv, env=None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dynatex", *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        env=env,
    )


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MiB tmpfs the test mounts (root on Linux), else the test is skipped."""
    if sys.platform != "linux" or os.geteuid() != 0:
        pytest.skip("a full disk is simulated with a small tmpfs, which only root can mount")
    mount = tmp_path / "small"
    mount.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mount)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {r.stderr.strip() or r.returncode}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def _one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    return lines[0]


def test_analysis_onto_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, small_disk):
    clip = tmp_path / "clip.npy"
    np.save(clip, wave_clip(t=60, h=64, w=64))  # its 50-component basis alone is 2.4 MB
    r = _dynatex("analyze", clip, "-o", small_disk / "db.h5", "-q")
    assert r.returncode == 2, r.stderr
    assert "no space left on device" in _one_line(r.stderr)
    assert os.listdir(small_disk) == []


def test_merge_onto_a_full_disk_keeps_the_database_and_leaves_nothing(tmp_path, small_disk):
    clips = []
    for i in range(2):
        clips.append(tmp_path / f"c{i}.npy")
        np.save(clips[-1], wave_clip(t=60, h=48, w=48, seed=i))
    small = tmp_path / "one.npy"
    np.save(small, wave_clip(t=20, h=8, w=8))
    db = small_disk / "db.h5"
    assert _dynatex("analyze", small, "-o", db, "-q", "--n", "3").returncode == 0
    before = db.read_bytes()
    r = _dynatex("analyze", *clips, "-o", tmp_path / "corpus", "--merge", db, "-q")
    assert r.returncode == 2, r.stderr
    assert "no space left on device" in _one_line(r.stderr)
    assert os.listdir(small_disk) == ["db.h5"] and db.read_bytes() == before


def test_a_video_onto_a_full_disk_says_so(tmp_path, small_disk):
    clip = tmp_path / "clip.npy"
    np.save(clip, wave_clip(t=60, h=32, w=32))
    db = tmp_path / "db.h5"
    assert _dynatex("analyze", clip, "-o", db, "-q", "--methods", "tiles").returncode == 0
    r = _dynatex(
        "play", db, "--mode", "tiles", "--backend", "numpy", "--size", "256x256", "--frames", "400",
        "-o", small_disk / "out.avi",
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    line = _one_line(r.stderr)
    assert "no space left on device" in line and " -" not in line.split("incomplete:")[-1]


def test_sigterm_ends_an_analysis_like_ctrl_c_and_removes_its_scratch(tmp_path, clips_dir):
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    env = dict(os.environ, TMPDIR=str(scratch))
    db = tmp_path / "db.h5"
    p = subprocess.Popen(
        [sys.executable, "-m", "dynatex", "analyze", clips_dir / "fire_flames_720p.mp4", "-o", db, "-q"],
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
    )
    deadline = time.monotonic() + 120
    while not any(n.startswith("dynatex-decode-") for n in os.listdir(scratch)):
        assert p.poll() is None and time.monotonic() < deadline, "the decode folder never appeared"
        time.sleep(0.05)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 143
    assert _one_line(err) == "dynatex: terminated"
    assert os.listdir(scratch) == [] and os.listdir(tmp_path) == ["scratch"]


def test_scratch_left_by_killed_runs_is_removed_and_a_live_runs_kept(tmp_path):
    stale_dir = tmp_path / "dynatex-decode-abcd1234"
    stale_dir.mkdir()
    (stale_dir / "frames.npy").write_bytes(b"x" * 100)
    stale_file = tmp_path / "dynatex-spill-zz_9yy8x.u8"
    stale_file.write_bytes(b"x" * 100)
    live = tmp_path / "dynatex-spill-live0000.u8"
    live.write_bytes(b"")
    other = tmp_path / "dynatex-decode-notours"  # seven characters: not a name of ours
    other.mkdir()
    held = hold(str(live))
    try:
        removed = remove_stale_scratch(str(tmp_path))
    finally:
        release(held)
    assert sorted(removed) == sorted([str(stale_dir), str(stale_file)])
    assert sorted(os.listdir(tmp_path)) == ["dynatex-decode-notours", "dynatex-spill-live0000.u8"]


def test_an_interrupt_raised_inside_a_finaliser_is_raised_again():
    from dynatex.cli import _catch_signals

    class RaisesOnDelete:
        def __del__(self):
            raise KeyboardInterrupt  # what Ctrl-C does when it lands in a finaliser

    restore = _catch_signals()
    try:
        with pytest.raises(KeyboardInterrupt):
            RaisesOnDelete()  # freed at once: Python can only report its interrupt as "ignored"
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:  # the interrupt, sent again, lands here
                time.sleep(0.01)
    finally:
        restore()
