"""Clip input: files, folders, arrays, ranges, geometry, and every kind of bad clip."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dynatex.analyzer import ClipError, load_clip

from ..conftest import wave_clip


def _write_video(path, frames, fps=12.0):
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (frames.shape[2], frames.shape[1]))
    for f in frames:
        w.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    w.release()


def test_array_range_crop_resize_grey():
    frames = wave_clip(t=20, h=16, w=24)
    clip = load_clip(frames, start=2, stop=12, step=2, crop=(4, 2, 16, 12), size=(6, 8))
    assert clip.frames.shape == (5, 6, 8, 3)  # size is (height, width)
    assert clip.source_size == (16, 24) and clip.source_info().source_size == (16, 24)
    assert clip.frame_start == 2 and clip.frame_step == 2 and clip.crop == (4, 2, 16, 12)
    grey = load_clip(frames, color=False)
    assert grey.frames.shape == (20, 16, 24, 1)
    info = grey.source_info()
    assert info.color_order == "GRAY" and info.pixels == 16 * 24


def test_video_file_round_trip(tmp_path):
    frames = wave_clip(t=15, h=32, w=48)
    path = tmp_path / "c.avi"
    _write_video(path, frames)
    clip = load_clip(path)
    assert clip.frames.shape == (15, 32, 48, 3)
    assert clip.fps == pytest.approx(12.0)
    assert np.abs(clip.frames.astype(int) - frames).mean() < 8  # MJPG is lossy
    assert len(clip.sha256) == 64
    isolated = load_clip(path, isolate=True)
    np.testing.assert_array_equal(isolated.frames, clip.frames)


def test_image_folder(tmp_path):
    frames = wave_clip(t=6, h=10, w=12)
    for i, f in enumerate(frames):
        cv2.imwrite(str(tmp_path / f"f{i:03d}.png"), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    clip = load_clip(tmp_path)
    np.testing.assert_array_equal(clip.frames, frames)


@pytest.mark.clips
def test_real_clip(clips_dir):
    clip = load_clip(clips_dir / "pendulum_clock_schoedl.mov")
    assert clip.frames.shape == (43, 240, 240, 3)


def test_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.avi: no such clip"):
        load_clip(tmp_path / "nope.avi")


def test_empty_and_garbage_files(tmp_path):
    empty = tmp_path / "empty.avi"
    empty.write_bytes(b"")
    with pytest.raises(ClipError, match="empty"):
        load_clip(empty)
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(np.random.default_rng(0).bytes(5000))
    with pytest.raises(ClipError, match="junk.mp4"):
        load_clip(junk)
    with pytest.raises(ClipError, match="junk.mp4"):
        load_clip(junk, isolate=True)


def test_one_frame_and_empty_range(tmp_path):
    path = tmp_path / "one.avi"
    _write_video(path, wave_clip(t=1, h=16, w=16))
    with pytest.raises(ClipError, match="only one frame"):
        load_clip(path)
    with pytest.raises(ClipError, match="no frames in range"):
        load_clip(wave_clip(t=5), start=10)


def test_empty_folder(tmp_path):
    with pytest.raises(ClipError, match="holds no images"):
        load_clip(tmp_path)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"step": 0}, "step must be at least 1"),
        ({"start": -1}, "start must be a non-negative integer"),
        ({"start": 5, "stop": 5}, "stop .* must be greater than start"),
        ({"crop": (0, 0, 100, 100)}, "crop .* does not fit"),
        ({"crop": (1, 2)}, "crop must be four"),
        ({"size": (0, 10)}, r"size must be \(height, width\) with each side in 1\.\.16384"),
        ({"size": (6.5, 8)}, r"size must be \(height, width\) integers"),
    ],
)
def test_bad_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        load_clip(wave_clip(t=10, h=16, w=16), **kwargs)


def test_bad_arrays():
    with pytest.raises(ClipError, match="must be \\(T, H, W\\)"):
        load_clip(np.zeros((4, 4), np.uint8))
    with pytest.raises(ClipError, match="within 0..255"):
        load_clip(np.full((3, 4, 4), 300.0))


def test_a_decoding_child_that_fails_is_one_clip_error_saying_how(tmp_path):
    """What the decoding child raised comes back as it was (a missing file stays FileNotFoundError);
    a crash or a hang there is a ClipError that says which, in one line."""
    from dynatex.analyzer.video import decoder_error
    from dynatex.child import call

    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"not a video" * 100)
    raised = call("dynatex.analyzer.video:_decode_to", str(junk), 0, None, 1, str(tmp_path / "f.npy"), timeout=120)
    error = decoder_error(str(junk), raised)
    assert isinstance(error, ClipError) and "junk.avi" in str(error) and "\n" not in str(error)
    crashed = decoder_error("c.mp4", call("os:abort", timeout=60))
    assert isinstance(crashed, ClipError) and str(crashed).startswith("c.mp4: the video decoder crashed (signal ")
    hung = decoder_error("h.mp4", call("time:sleep", 60, timeout=1))
    assert str(hung).startswith("h.mp4: the video decoder did not finish within 1 s; re-encode the clip")
    missing = call("dynatex.analyzer.video:_decode_to", str(tmp_path / "no.mp4"), 0, None, 1, "x.npy", timeout=120)
    assert type(decoder_error("no.mp4", missing)) is FileNotFoundError
