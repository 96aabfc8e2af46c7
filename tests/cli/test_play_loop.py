"""``dynatex play --loop`` and ``Player.frames(count, loop=True)``: the last frame leads into the
first as any other step does, for tiles, turnpoints and the crossfaded modes; the wrap is reported."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.metrics import temporal_discontinuity
from dynatex.analyzer.tiles import learn_tiles
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
from dynatex.cli import main
from dynatex.player import open_player
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    """One texture with frames, tiles and turn points."""
    frames = pendulum_clip(72, 48)[0]
    clip = load_clip(frames)
    path = tmp_path_factory.mktemp("loop") / "t.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
        w.put_method("t", "turnpoints", learn_turnpoints(clip))
    waves = load_clip(wave_clip(60, 40, 48))
    with DatabaseWriter(path) as w:
        w.put_texture("w", waves.source_info())
        w.put_frames("w", waves.frames)
        w.put_method("w", "tiles", learn_tiles(waves.frames, min_loop=16))
    return path


def _play(capsys, *argv) -> tuple[np.ndarray, float]:
    out = argv[argv.index("-o") + 1]
    out.mkdir(exist_ok=True)
    assert main(["play", *map(str, argv), "--backend", "numpy"]) == 0
    err = capsys.readouterr().err
    ratio = float(
        re.search(r"wrap discontinuity ([0-9.]+) x the median frame step of the (?:source|export)", err).group(1)
    )
    files = sorted(out.glob("*.png"))
    frames = np.stack([cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB) for f in files])
    return frames, ratio


def _wrap_and_steps(frames: np.ndarray, source: np.ndarray) -> tuple[float, np.ndarray]:
    """The wrap's step and the other steps, over the source's median step."""
    seq = np.concatenate([frames, frames[:1]])
    steps = temporal_discontinuity(seq, list(range(1, len(seq))), source=source)
    return float(steps[-1]), steps[:-1]


@pytest.mark.parametrize(("texture", "mode", "frames"), [("w", "tiles", 40), ("t", "turnpoints", 60)])
def test_native_loops_close(db, tmp_path, capsys, texture, mode, frames):
    out, ratio = _play(capsys, db, "--texture", texture, "--mode", mode, "--frames", frames, "--loop", "-o", tmp_path)
    with open_player(db, texture, mode=mode, backend="numpy") as p:
        turns = p.model.turn_points if mode == "turnpoints" else None
        length = p.loop_length if mode == "tiles" else 2 * int(np.diff(turns).max())
    assert len(out) == length * max(1, round(frames / length))  # whole loops at the source's pace
    with open_player(db, texture, mode=mode, backend="numpy") as p:
        source = p.texture.frames().read()
    wrap, steps = _wrap_and_steps(out, source)
    assert ratio == pytest.approx(wrap, abs=0.01)
    assert wrap <= 1.0 and wrap <= steps.max()  # an ordinary step: at most the source's median
    assert len(np.unique(out.reshape(len(out), -1), axis=0)) > len(out) // 4  # it moves


def test_crossfaded_loop_brings_the_wrap_down(lds_db, tmp_path, capsys):
    loop, ratio = _play(capsys, lds_db, "--mode", "lds", "--frames", 40, "--loop", "-o", tmp_path / "a")
    (tmp_path / "b").mkdir()
    argv = ["play", str(lds_db), "--mode", "lds", "--frames", "40", "--backend", "numpy", "-o", str(tmp_path / "b")]
    assert main(argv) == 0
    plain = np.stack([cv2.imread(str(f)) for f in sorted((tmp_path / "b").glob("*.png"))])[..., ::-1]
    before = float(temporal_discontinuity(np.concatenate([plain, plain[:1]]), [40], source=plain)[0])
    after = float(temporal_discontinuity(np.concatenate([loop, loop[:1]]), [40], source=plain)[0])
    assert after <= 1.5 < before, (after, before)
    assert len(loop) == 40 and ratio <= 1.5


def test_python_api_loop(db):
    with open_player(db, "w", mode="tiles", backend="numpy", seed=3) as p:
        frames = np.stack(list(p.frames(30, loop=True)))
        length = p.loop_length
    n = length * max(1, round(30 / length))
    assert len(frames) == n
    with open_player(db, "w", mode="tiles", backend="numpy", seed=3) as p:
        p.epoch = 0
        again = np.stack(list(p.frames(n + 1)))
    assert np.array_equal(again[n], again[0])  # the tile loop closes
    start = next(k for k in range(n) if np.array_equal(again[k], frames[0]))
    assert np.array_equal(frames, np.roll(again[:n], -start, axis=0))  # the same cycle, rotated


def test_loop_refuses_speed_with_native_loops_and_inpaint(db, tmp_path, capsys):
    argv = ["play", str(db), "--texture", "w", "--mode", "tiles", "--loop", "--backend", "numpy", "-o", str(tmp_path)]
    assert main([*argv, "--speed", "2"]) == 2
    assert "--speed is set by --loop" in capsys.readouterr().err
