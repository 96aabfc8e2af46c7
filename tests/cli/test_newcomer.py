"""The command line a newcomer meets: the texture's own mode by default, a usage error that points
to the mode's help, readable ``info``, and the small defaults the first hour tripped on."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import h5py
import pytest

from dynatex.cli import main
from dynatex.commands.info import summary

from ..conftest import verified_devices

SELFTEST = str(resources.files("dynatex.player").joinpath("selftest.h5"))


def _only(tmp_path, method: str) -> str:
    path = tmp_path / f"{method}.h5"
    path.write_bytes(Path(SELFTEST).read_bytes())
    with h5py.File(path, "r+") as f:
        tex = f["textures/selftest"]
        for name in list(tex):
            if name not in (method, "source", "frames"):
                del tex[name]
    return str(path)


def test_play_without_mode_plays_the_only_method_the_texture_holds(tmp_path, capsys):
    db = _only(tmp_path, "tiles")
    out = tmp_path / "frames"
    out.mkdir()
    assert main(["play", db, "--frames", "2", "-o", str(out), "--backend", "numpy"]) == 0
    assert len(list(out.glob("*.png"))) == 2
    assert main(["play", db, "--mode", "lds", "--frames", "2", "-o", str(out), "--backend", "numpy"]) == 2
    err = capsys.readouterr().err
    assert "it plays now as --mode tiles" in err and err.index("--mode tiles") < err.index("dynatex analyze"), err


def test_play_help_without_mode_lists_the_textures_mode(tmp_path, capsys):
    db = _only(tmp_path, "quilt")
    with pytest.raises(SystemExit):
        main(["play", db, "--help"])
    page = capsys.readouterr().out
    assert "evolve controls:" in page and "this help lists mode evolve's" in page
    assert "--no-interpolate" in page and "turn off what is on by default: Blend linearly" in page


def test_quilt_is_accepted_as_the_evolve_mode(tmp_path):
    db = _only(tmp_path, "quilt")
    out = tmp_path / "q"
    out.mkdir()
    assert main(["play", db, "--mode", "quilt", "--frames", "1", "-o", str(out), "--backend", "numpy"]) == 0


def test_a_flag_of_another_mode_points_to_the_modes_own_help(capsys):
    with pytest.raises(SystemExit) as info:
        main(["play", SELFTEST, "--mode", "mixture", "--speed", "0.5", "-o", "x.mp4"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "unrecognized arguments: --speed 0.5" in err
    assert "(see `dynatex play --mode mixture --help`)" in err, err


def test_evolve_holding_its_end_stops_when_the_clock_reaches_it(tmp_path, capsys):
    db = _only(tmp_path, "quilt")
    out = tmp_path / "ev"
    out.mkdir()
    assert main(["play", db, "-o", str(out), "--backend", "numpy", "--speed", "2"]) == 0
    assert len(list(out.glob("*.png"))) == 25  # times 0, 2, ..., 46, then 47 held once: not 250 frames
    out2 = tmp_path / "loop"
    out2.mkdir()
    assert main(["play", db, "-o", str(out2), "--backend", "numpy", "--end", "loop", "--frames", "60"]) == 0
    assert len(list(out2.glob("*.png"))) == 60


def test_info_summarises_long_lists_and_names_modes_and_controls(tmp_path, capsys):
    db = _only(tmp_path, "tiles")
    assert main(["info", db]) == 0
    text = capsys.readouterr().out
    assert "plays as: --mode tiles (default)" in text
    assert "mode tiles (plays tiles)" in text and "speed          a finite number in [-4, 4] (default 1)" in text
    assert main(["info", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["textures"]["selftest"]["modes"] == ["tiles"] and "tiles" in doc["modes"]


def test_long_lists_print_as_a_summary():
    assert summary(list(range(80))) == "80 values: min 0, median 39.5, max 79 (all of them: --json)"
    assert summary([[1, 2, 3]] * 9).startswith("9x3 values: min 1, median 2, max 3")
    assert summary(["a"] * 9) == "9 entries: a, a, a, ... (all of them: --json)"
    assert summary([0.5] * 8) == [0.5] * 8  # short lists stay as they are


def test_bench_takes_a_size_for_a_mode_of_any_size(tmp_path, capsys):
    db = _only(tmp_path, "tiles")
    assert main(["bench", "--size", "40x24"]) == 2  # --size belongs to a database's benchmark
    capsys.readouterr()
    code = main(["bench", db, "--size", "40x24", "--frames", "2", "--json"])
    if not verified_devices():  # the broken-driver case: bench compares OpenCL with numpy, and says so
        assert code == 2 and "no OpenCL device here passed the self-test" in capsys.readouterr().err
        return
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["results"][0]["mode"] == "tiles"
