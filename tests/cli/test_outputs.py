"""Browser-playable video and animated images: ``dynatex play -o`` chooses the writer by extension;
each output is read back (PyAV for H.264, Pillow for WebP/APNG/GIF) with its codec, frame count,
timing and pixels checked."""

from __future__ import annotations

import io
import sys

import av
import numpy as np
import pytest
from PIL import Image

from dynatex.cli import OutputError, main
from dynatex.commands._output import ANIMATIONS, FrameWriter, read_animation
from dynatex.player import open_player

#: Lowest PSNR (dB) of an H.264 frame decoded back, against the frame written (CRF 17, yuv420p):
#: these small, saturated test frames lose most to the halved chroma resolution.
H264_PSNR_DB = 32.0


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def _decode(path) -> tuple[str, str, list[np.ndarray]]:
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        frames = [f.to_ndarray(format="rgb24") for f in c.decode(s)]
        return s.codec_context.name, s.codec_context.pix_fmt, frames


def _smooth_frames(n: int, h: int, w: int) -> list[np.ndarray]:
    """Distinct frames a texture might look like: moving colour gradients."""
    y, x = np.mgrid[0:h, 0:w]
    return [
        np.stack([128 + 100 * np.sin(x / 7 + t / 3 + c) * np.cos(y / 9 - t / 5) for c in range(3)], -1).astype(np.uint8)
        for t in range(n)
    ]


def test_play_writes_h264_that_decodes_back_within_psnr(lds_db, tmp_path, capsys):
    out = tmp_path / "o.mp4"
    assert main(["play", str(lds_db), "-o", str(out), "--frames", "12", "--backend", "numpy", "--fps", "25"]) == 0
    codec, pix_fmt, frames = _decode(out)
    assert (codec, pix_fmt, len(frames)) == ("h264", "yuv420p", 12)
    with av.open(str(out)) as c:
        assert float(c.streams.video[0].average_rate) == pytest.approx(25.0)
    with open_player(lds_db, backend="numpy", seed=0) as p:
        expected = [p.next_frame().copy() for _ in range(12)]
    worst = min(_psnr(a, b) for a, b in zip(frames, expected))
    assert worst >= H264_PSNR_DB, worst


def test_odd_sizes_are_padded_to_even_by_repeating_the_edge(tmp_path):
    frames = _smooth_frames(6, 33, 47)
    w = FrameWriter(str(tmp_path / "odd.mp4"))
    w.open((33, 47, 3), 30.0)
    for f in frames:
        w.write(f)
    w.close()
    codec, _, back = _decode(tmp_path / "odd.mp4")
    assert codec == "h264" and len(back) == 6 and back[0].shape == (34, 48, 3)
    assert min(_psnr(b[:33, :47], f) for b, f in zip(back, frames)) >= H264_PSNR_DB
    assert _psnr(back[0][33, :47], back[0][32, :47]) >= H264_PSNR_DB  # the padding repeats the last row


@pytest.mark.parametrize("ext", sorted(ANIMATIONS))
@pytest.mark.parametrize("fps", [10.0, 29.97])
def test_animated_images_read_back_with_frame_count_and_timing(tmp_path, ext, fps):
    frames = _smooth_frames(9, 20, 28)
    out = tmp_path / f"a{ext}"
    w = FrameWriter(str(out))
    w.open((20, 28, 3), fps)
    for f in frames:
        w.write(f)
    w.close()
    count, delays = read_animation(str(out))
    tick_ms = ANIMATIONS[ext].tick * 1000
    assert count == 9
    assert all(abs(d - 1000 / fps) <= tick_ms for d in delays), delays  # each delay rounded to a tick
    assert abs(sum(delays) - 9000 / fps) <= tick_ms / 2 + 1e-9, delays  # and the total does not drift
    with Image.open(out) as im:
        assert im.info.get("loop") == 0  # loops for ever
        im.seek(4)
        back = np.asarray(im.convert("RGB"))
    assert back.shape == (20, 28, 3)
    assert _psnr(back, frames[4]) >= (20.0 if ext == ".gif" else 30.0)  # GIF: 256 colours a frame


def test_play_chooses_the_writer_by_extension(lds_db, tmp_path, capsys):
    for ext in (".gif", ".webp", ".apng"):
        out = tmp_path / f"o{ext}"
        assert main(["play", str(lds_db), "-o", str(out), "--frames", "5", "--fps", "20", "--backend", "numpy"]) == 0
        with Image.open(out) as im:
            assert im.format == ANIMATIONS[ext].pillow and getattr(im, "is_animated", False)
        assert sum(read_animation(str(out))[1]) == 250


@pytest.mark.parametrize("ext, fps, what", [(".gif", 60.0, "[0.01, 50]"), (".apng", 0.01, "[0.01526, 1000]")])
def test_rate_an_animation_cannot_time_is_refused_before_writing(tmp_path, ext, fps, what):
    out = tmp_path / f"o{ext}"
    with pytest.raises(OutputError, match=rf"take \{what}"):
        FrameWriter(str(out)).open((8, 8, 3), fps)
    assert not out.exists()


def test_unknown_extension_names_the_choices(tmp_path):
    with pytest.raises(OutputError, match=r"\.mp4.*\.webp.*\.apng"):
        FrameWriter(str(tmp_path / "o.xyz"))


def test_animation_opened_without_frames_leaves_no_file(tmp_path):
    out = tmp_path / "o.webp"
    w = FrameWriter(str(out))
    w.open((8, 8, 3), 10.0)
    assert out.exists()  # created at open, so that the OS's refusal comes first
    w.close()
    assert not out.exists()


def test_crf_and_preset_trade_size_for_quality(tmp_path):
    """A lower CRF keeps more (a larger file, a higher PSNR); every preset writes H.264 that
    decodes back whole; values outside x264's are refused before anything is written."""
    frames = _smooth_frames(8, 64, 96)
    sizes, psnr = {}, {}
    for crf, preset in ((10, "ultrafast"), (40, "ultrafast"), (17, "veryfast")):
        path = tmp_path / f"c{crf}.mp4"
        with FrameWriter(str(path), crf=crf, preset=preset) as w:
            w.open(frames[0].shape, 25.0, len(frames))
            for f in frames:
                w.write(f)
        codec, _, back = _decode(path)
        assert codec == "h264" and len(back) == len(frames)
        sizes[crf], psnr[crf] = path.stat().st_size, min(_psnr(a, b) for a, b in zip(back, frames))
    assert sizes[10] > sizes[17] > sizes[40] and psnr[10] > psnr[40]
    with pytest.raises(ValueError, match=r"crf must be an integer in \[0, 51\], not 52"):
        FrameWriter(str(tmp_path / "x.mp4"), crf=52)
    with pytest.raises(ValueError, match=r"preset must be one of \('ultrafast'.*not 'fastest'"):
        FrameWriter(str(tmp_path / "x.mp4"), preset="fastest")
    assert not (tmp_path / "x.mp4").exists()


def test_play_refuses_a_crf_out_of_range(lds_db, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:  # argparse's usage error
        main(["play", str(lds_db), "--frames", "2", "--crf", "60", "-o", str(tmp_path / "o.mp4")])
    assert e.value.code == 2
    assert "--crf" in capsys.readouterr().err and not (tmp_path / "o.mp4").exists()


class _Terminal(io.StringIO):
    """What a terminal would receive (tqdm draws only where stderr is one)."""

    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("ext", [".mp4", ".gif"])
def test_a_progress_bar_counts_frames_on_a_terminal(tmp_path, monkeypatch, ext):
    """With progress on, a terminal sees the frames written counted against the total (and for an
    animated image, the frames encoded at close); elsewhere nothing is drawn."""
    from dynatex.commands import _output

    monkeypatch.setattr(_output, "PROGRESS_DELAY", 0.0)
    frames = _smooth_frames(5, 32, 48)
    for tty in (True, False):
        err = _Terminal() if tty else io.StringIO()
        monkeypatch.setattr(sys, "stderr", err)
        with FrameWriter(str(tmp_path / f"p{tty}{ext}"), progress=True) as w:
            w.open(frames[0].shape, 10.0, len(frames))
            for f in frames:
                w.write(f)
        text = err.getvalue()
        if tty:
            assert "writing" in text and "5/5" in text, text
            assert ("encoding" in text) == (ext == ".gif"), text
        else:
            assert text == ""
