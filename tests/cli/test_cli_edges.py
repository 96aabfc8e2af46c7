"""Odd command-line input: every numeric option checked up front, one-line usage errors, the
output writer's failures and a closed pipe, each run as a real ``dynatex`` process."""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.cli import build_parser, main
from dynatex.tiledb import DatabaseWriter, open_db

from ..conftest import wave_clip

#: Positional and required arguments that let each subcommand's parser reach the option under test.
REQUIRED = {
    "analyze": ["clip.npy", "-o", "x.h5"],
    "info": ["db.h5"],
    "play": ["db.h5", "-o", "x.mp4"],
    "bench": [],
    "evaluate": ["a.npy", "b.npy"],
    "demo": [],
    "export": ["db.h5", "-o", "out"],
}
NOISE = ("cap_ffmpeg", "[mpeg4", "VIDEOIO", "Traceback", "usage:")


def _dynatex(*argv, timeout: float = 120, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dynatex", *map(str, argv)],
        capture_output=True,
        text=True,
        check=False,
        timeout=timeout,
        **kwargs,
    )


def _one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert not any(n in stderr for n in NOISE), stderr
    return lines[0]


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _numeric_actions():
    """``(command, action, rule)`` of every option that parses numbers: an argparse type of
    ``_common`` or a kind of :mod:`dynatex.checks` behind a ``KindArg``."""
    from dynatex import checks
    from dynatex.commands._common import KindArg, Number, Numbers, size_arg

    for cmd, p in _subparsers().items():
        for action in p._actions:
            rule = action.type.rule if isinstance(action.type, KindArg) else action.type
            if isinstance(rule, (Number, Numbers, checks.Range, checks.Numbers, checks.Size)) or rule is size_arg:
                yield cmd, action, rule


def _outside(n) -> list[str]:
    """Values just outside ``n``'s declared range, and values no range takes."""
    bad = ["nan", "inf", "-inf", "x"]
    if n.low is not None:
        below = n.low - 1 if n.kind is int else math.nextafter(n.low, -math.inf)
        bad.append(repr(n.low if n.low_open else below))
    if n.high is not None:
        above = n.high + 1 if n.kind is int else math.nextafter(n.high, math.inf)
        bad.append(repr(n.high if n.high_open else above))
    if n.kind is int:
        bad.append("1.5")
    return bad


def _inside(n) -> list[str]:
    """The closed ends of ``n``'s range, or a value inside it."""
    vals = [v for v, is_open in ((n.low, n.low_open), (n.high, n.high_open)) if v is not None and not is_open]
    if not vals:
        lo, hi = n.low, n.high
        vals = [
            (lo + hi) / 2
            if lo is not None and hi is not None
            else lo + 1
            if lo is not None
            else hi - 1
            if hi is not None
            else 1
        ]
    return [repr(n.kind(v)) for v in vals]


# -- every numeric option --------------------------------------------------------------------------
def test_every_numeric_option_declares_a_range():
    """No option parses numbers with a bare int or float (which take nan, inf and any size)."""
    bare = [
        f"{cmd} {a.option_strings}" for cmd, p in _subparsers().items() for a in p._actions if a.type in (int, float)
    ]
    assert bare == []
    assert len(list(_numeric_actions())) >= 50


def test_numeric_options_refuse_values_outside_their_declared_range(capsys):
    from dynatex import checks
    from dynatex.commands._common import Number, Numbers

    checked = 0
    for cmd, action, rule in _numeric_actions():
        opt = action.option_strings[-1]
        if isinstance(rule, (Number, checks.Range)):
            bad = _outside(rule)
        elif isinstance(rule, (Numbers, checks.Numbers)):
            good = _inside(rule.item)[0]
            bad = [",".join([good] * (rule.count - 1) + [v]) for v in _outside(rule.item)]
            bad.append(",".join([good] * (rule.count + 1)))
        else:
            bad = ["0x0", "16385x8", "8x", "nanxnan"]
        for value in bad:
            with pytest.raises(SystemExit) as e:
                main([cmd, *REQUIRED[cmd], f"{opt}={value}"])
            assert e.value.code == 2
            _, err = capsys.readouterr()
            line = _one_line(err)
            assert line.startswith(f"dynatex {cmd}: error: argument {opt}"), line
            assert line.endswith(f"(see `dynatex {cmd} --help`)"), line
            checked += 1
    assert checked > 300


def test_numeric_options_take_the_ends_of_their_range():
    from dynatex import checks
    from dynatex.commands._common import Number

    parsers = _subparsers()
    for cmd, action, rule in _numeric_actions():
        if isinstance(rule, (Number, checks.Range)):
            for value in _inside(rule):
                args = parsers[cmd].parse_args([*REQUIRED[cmd], f"{action.option_strings[-1]}={value}"])
                assert math.isfinite(getattr(args, action.dest))


def test_help_states_the_declared_range(capsys):
    from dynatex.commands._output import MAX_FPS, MIN_FPS

    with pytest.raises(SystemExit):
        main(["play", "--help"])
    out = capsys.readouterr().out
    assert f"in [{MIN_FPS:g}, {MAX_FPS:g}]" in " ".join(out.split())


# -- one-line usage errors -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, command, where",
    [
        (("play", "db.h5", "-o", "o.mp4", "--frames", "0"), "play", "--frames"),
        (("play", "db.h5", "-o", "o.mp4", "--size", "0x0"), "play", "--size"),
        (("analyze", "c.npy", "-o", "o.h5", "--step", "0"), "analyze", "--step"),
        (("info", "db.h5", "--bogus"), "info", "--bogus"),
    ],
)
def test_usage_errors_are_one_line_pointing_to_help(argv, command, where):
    r = _dynatex(*argv)
    line = _one_line(r.stderr)
    assert r.returncode == 2
    assert line.startswith(f"dynatex {command}: error: ") and where in line
    assert line.endswith(f"(see `dynatex {command} --help`)")


@pytest.mark.parametrize(
    "argv, prog, where",
    [
        (("play", "db.h5"), "dynatex play", "-o/--output"),
        (("frob",), "dynatex", "frob"),
        ((), "dynatex", "COMMAND"),
    ],
)
def test_more_usage_errors_are_one_line(capsys, argv, prog, where):
    with pytest.raises(SystemExit) as e:
        main(list(argv))
    line = _one_line(capsys.readouterr().err)
    assert e.value.code == 2 and where in line and line.endswith(f"(see `{prog} --help`)")


# -- frame rates --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ext", [".mp4", ".avi"])
def test_infinite_fps_is_refused_instead_of_hanging(lds_db, tmp_path, ext):
    out = tmp_path / f"o{ext}"
    r = _dynatex("play", lds_db, "-o", out, "--frames", "1", "--fps", "inf", "--backend", "numpy", timeout=60)
    assert r.returncode == 2
    assert "argument --fps" in _one_line(r.stderr)
    assert not out.exists()


@pytest.mark.parametrize("fps", ["nan", "1e9", "-5", "0"])
def test_bad_fps_exits_2_with_one_line(lds_db, tmp_path, fps):
    out = tmp_path / "o.mp4"
    r = _dynatex("play", lds_db, "-o", out, "--frames", "2", "--fps", fps, "--backend", "numpy")
    assert r.returncode == 2  # 0 was silently 25 fps, the others exit 1 with FFmpeg's log
    assert f"not '{fps}'" in _one_line(r.stderr)
    assert not out.exists()


@pytest.mark.parametrize("fps", [0, -5, math.nan, math.inf, -math.inf, 1e9, 0.0099, 1000.1])
def test_writer_refuses_any_fps_it_cannot_write(tmp_path, fps):
    from dynatex.cli import OutputError
    from dynatex.commands._output import FrameWriter

    out = tmp_path / "o.mp4"
    with pytest.raises(OutputError, match="frame rate"):
        FrameWriter(str(out)).open((24, 32, 3), fps)
    assert not out.exists()


def test_writer_writes_every_container_at_the_ends_of_its_fps_range(tmp_path):
    """In a child process with a timeout: a frame rate the writer takes must never hang OpenCV."""
    code = (
        "import sys, cv2, numpy as np\n"
        "from dynatex.commands._output import FrameWriter, MIN_FPS, MAX_FPS\n"
        "for ext in ('.mp4', '.avi', '.mkv'):\n"
        "    for fps in (MIN_FPS, 1 / 3, 23.976, 29.97, MAX_FPS):\n"
        "        path = f'{sys.argv[1]}/v{fps}{ext}'\n"
        "        w = FrameWriter(path)\n"
        "        w.open((24, 32, 3), fps)\n"
        "        for i in range(3):\n"
        "            w.write(np.full((24, 32, 3), 60 * i, np.uint8))\n"
        "        w.close()\n"
        "        cap = cv2.VideoCapture(path)\n"
        "        n = 0\n"
        "        while cap.read()[0]:\n"
        "            n += 1\n"
        "        assert n == 3, (path, n)\n"
        "print('ok')\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, check=False, timeout=120
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr
    assert r.stderr == ""


# -- the output writer's failures ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def wide_db(tmp_path_factory):
    """A texture 8200 pixels wide: more than MPEG-4 takes, less than Motion JPEG does."""
    clip = load_clip(wave_clip(t=12, h=16, w=8200))
    path = tmp_path_factory.mktemp("wide") / "wide.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("wide", clip.source_info())
        w.put_method("wide", "lds", learn_lds(clip, n=3))
    return path


def test_frame_size_the_codec_refuses_exits_2_with_the_reason(wide_db, tmp_path):
    r = _dynatex("play", wide_db, "-o", tmp_path / "o.mp4", "--frames", "1", "--backend", "numpy")
    line = _one_line(r.stderr)
    assert r.returncode == 2 and "8200x16" in line and "2..8191" in line and ".avi" in line
    assert not (tmp_path / "o.mp4").exists()
    r = _dynatex("play", wide_db, "-o", tmp_path / "o.avi", "--frames", "1", "--backend", "numpy")
    assert r.returncode == 0, r.stderr


def _long_name(d):
    return d / ("x" * 300 + ".mp4")


def _device_link(d):
    os.symlink("/dev/full", d / "full.mp4")
    return d / "full.mp4"


def _full_png_folder(d):
    os.mkdir(d / "frames")
    os.symlink("/dev/full", d / "frames" / "frame_00000.png")
    return str(d / "frames") + os.sep


@pytest.mark.parametrize(
    "make, reason",
    [
        (lambda d: d / "missing" / "o.mp4", "does not exist"),
        (_long_name, "File name too long"),
        (_device_link, "not a regular file"),
        (_full_png_folder, "No space left on device"),
    ],
    ids=["missing-folder", "name-too-long", "device", "disk-full-png"],
)
def test_output_writer_failure_exits_2_with_the_reason(lds_db, tmp_path, make, reason):
    if "full" in getattr(make, "__name__", "") and not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    out = make(tmp_path)
    r = _dynatex("play", lds_db, "-o", out, "--frames", "2", "--backend", "numpy")
    assert r.returncode == 2
    assert reason in _one_line(r.stderr)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_exits_2(lds_db, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        r = _dynatex("play", lds_db, "-o", folder / "o.mp4", "--frames", "2", "--backend", "numpy")
    finally:
        folder.chmod(0o755)
    assert r.returncode == 2 and "Permission denied" in _one_line(r.stderr)


def test_video_that_does_not_read_back_whole_is_an_error(tmp_path):
    """What a full disk does to a video (its index never written) is caught when the writer closes."""
    from dynatex.cli import OutputError
    from dynatex.commands._output import FrameWriter

    out = tmp_path / "o.avi"
    w = FrameWriter(str(out))
    w.open((24, 32, 3), 25.0)
    for i in range(3):
        w.write(np.full((24, 32, 3), i, np.uint8))
    out.unlink()  # OpenCV keeps writing the unlinked file; the path holds nothing
    out.write_bytes(b"")
    with pytest.raises(OutputError, match="incomplete: 0 of 3 frames"):
        w.close()


def test_opencv_log_is_kept_off_the_terminal_and_becomes_the_reason(tmp_path, capfd):
    from dynatex.commands._output import FrameWriter

    w = FrameWriter(str(tmp_path / "o.mp4"))
    w.open((24, 32, 3), 25.0)
    with w._quiet("test"):
        os.write(2, b"[ERROR:0@0.1] global cap_ffmpeg_impl.hpp:1 open Could not open codec\n")
    assert capfd.readouterr().err == ""
    assert w._reason("refused").endswith("(global cap_ffmpeg_impl.hpp:1 open Could not open codec)")
    w.write(np.zeros((24, 32, 3), np.uint8))
    w.close()
    cap = cv2.VideoCapture(str(tmp_path / "o.mp4"))
    assert cap.read()[0]
    cap.release()


# -- a closed pipe ------------------------------------------------------------------------------------------------
def _reader_gone(argv, closed: str) -> tuple[int, bytes]:
    """Run ``dynatex ARGV`` with its ``closed`` pipe ("stdout" or "stderr") closed by the reader before
    the first line, as ``| head -0`` would; the exit code and what came on the other pipe."""
    with subprocess.Popen(
        [sys.executable, "-m", "dynatex", *map(str, argv)], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    ) as p:
        getattr(p, closed).close()
        other = (p.stderr if closed == "stdout" else p.stdout).read()
        return p.wait(timeout=120), other


@pytest.mark.parametrize("json", [False, True])
def test_closed_stdout_of_info_ends_quietly(lds_db, json):
    code, err = _reader_gone(["info", lds_db] + (["--json"] if json else []), "stdout")
    assert code == 0  # exit 1 with "internal error: BrokenPipeError" before
    assert err == b""


def test_closed_stdout_after_analysis_keeps_the_database(tmp_path):
    clip = tmp_path / "c.npy"
    np.save(clip, wave_clip(t=30, h=16, w=16))
    db = tmp_path / "c.h5"
    code, err = _reader_gone(["analyze", clip, "-o", db, "--n", "4"], "stdout")
    assert code == 0
    assert b"BrokenPipe" not in err and b"error" not in err
    assert db.exists()


def test_closed_stderr_drops_the_diagnostics_not_the_work(tmp_path):
    """An analysis whose stderr reader went away still writes its database and says so on stdout."""
    clip = tmp_path / "c.npy"
    np.save(clip, wave_clip(t=30, h=16, w=16))
    db = tmp_path / "c.h5"
    code, out = _reader_gone(["analyze", clip, "-o", db, "--n", "4"], "stderr")  # summaries go to stderr
    assert code == 0
    assert out.decode().startswith("wrote texture 'c'")
    with open_db(db) as d:
        assert d.textures == ("c",)


def test_closed_stderr_of_play_ends_quietly(lds_db, tmp_path):
    out = tmp_path / "o.mp4"
    code, stdout = _reader_gone(["play", lds_db, "-o", out, "--frames", "3", "--backend", "numpy"], "stderr")
    assert code == 0 and stdout == b""
    assert out.stat().st_size > 0


# -- default texture names ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "filename, texture", [("my clip é.avi", "my clip é"), ("水.mp4", "水"), (".hidden clip.npy", "hidden clip")]
)
def test_default_texture_name_of_any_clip_name_is_accepted(tmp_path, capsys, filename, texture):
    clip = tmp_path / filename
    frames = wave_clip(t=24, h=16, w=16)
    if filename.endswith(".npy"):
        np.save(clip, frames)
    else:
        fourcc = {".avi": "MJPG", ".mp4": "mp4v"}[os.path.splitext(filename)[1]]
        v = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*fourcc), 25.0, (16, 16))
        for f in frames:
            v.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        v.release()
    db = tmp_path / "db.h5"
    r = _dynatex("analyze", clip, "-o", db, "--n", "4", "-q")
    assert r.returncode == 0, r.stderr  # exit 2 "texture name ... is invalid" before
    assert main(["info", str(db), "--json"]) == 0
    assert list(json.loads(capsys.readouterr().out)["textures"]) == [texture]
    assert (
        main(
            [
                "play",
                str(db),
                "--texture",
                texture,
                "--frames",
                "2",
                "-o",
                str(tmp_path / "o.avi"),
                "--backend",
                "numpy",
            ]
        )
        == 0
    )
