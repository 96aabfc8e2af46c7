"""Modes describe themselves: declared options match the constructors, declared controls check,
save and restore themselves, and a new control reaches the CLI, the state and the docs from
its one declaration."""

from __future__ import annotations

import importlib.util
import inspect
from pathlib import Path

import numpy as np
import pytest

from dynatex.checks import Range
from dynatex.cli import main
from dynatex.errors import DynatexError
from dynatex.player import MODES, open_player, player_class
from dynatex.player.base import COMMON_OPTIONS
from dynatex.player.controls import Control, controls_of
from dynatex.player.modes import lds
from dynatex.player.opencl import selftest

OPTIONS = {"lds": {}, "mixture": {}, "turnpoints": {}, "tiles": {"size": (40, 72)}, "evolve": {}}


@pytest.mark.parametrize("mode", sorted(MODES))
def test_declared_options_are_the_constructor_keywords(mode):
    cls = player_class(mode)
    signature = inspect.signature(cls.__init__).parameters
    keywords = {n for n, p in signature.items() if p.kind is p.KEYWORD_ONLY}
    declared = {p.name for p in (*COMMON_OPTIONS, *cls.options)} - {"db", "texture"}
    controls_taken = {n for n in keywords if n in cls.controls()}  # initial values of controls
    assert keywords - controls_taken == declared, mode
    for p in cls.options:
        default = signature[p.name].default
        assert default is p.default or default == p.default, (mode, p.name)


@pytest.mark.parametrize("mode", sorted(MODES))
def test_controls_start_at_their_defaults_and_refuse_values_outside_their_rule(mode):
    db = selftest._db_path()
    with open_player(db, selftest.TEXTURE, mode=mode, backend="numpy", **OPTIONS[mode]) as p:
        assert p.controls(), mode
        for name, control in p.controls().items():
            default = control.param.default
            if default is not None:
                value = getattr(p, name)
                assert np.array_equal(np.asarray(value), np.asarray(default)), (mode, name, value)
            before = control.saved(p)
            with pytest.raises((DynatexError, ValueError, TypeError)):
                setattr(p, name, "not a value")
            assert np.array_equal(np.asarray(control.saved(p), dtype=object), np.asarray(before, dtype=object))
        state = p.get_state()
        assert set(p.controls()) <= state.keys()


@pytest.mark.parametrize("mode", sorted(MODES))
def test_the_docstring_lists_every_option_and_control(mode):
    cls = player_class(mode)
    doc = cls.__doc__
    for p in (*COMMON_OPTIONS, *cls.options, *(c.param for c in cls.controls().values())):
        assert f"\n    {p.name} : " in doc, (mode, p.name)
    assert doc.index("Controls (attributes") < doc.index("    Examples") if "    Examples" in doc else True


@pytest.mark.parametrize("mode", sorted(MODES))
def test_play_offers_exactly_the_flags_of_its_mode(mode, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["play", "--mode", mode, "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    cls = player_class(mode)
    for c in cls.controls().values():
        if c.param.flag_name:
            assert c.param.flag_name in text, (mode, c.name)
    others = {
        c.param.flag_name for m in MODES if m != mode for c in player_class(m).controls().values() if c.param.flag_name
    } - {c.param.flag_name for c in cls.controls().values()}
    assert not [f for f in others if f + " " in text], (mode, others)


def test_a_flag_of_another_mode_is_an_argparse_usage_error(tmp_path, capsys):
    code = None
    try:
        main(
            [
                "play",
                str(tmp_path / "x.h5"),
                "--mode",
                "tiles",
                "--rate-map",
                "halves:1,2",
                "-o",
                str(tmp_path / "x.mp4"),
            ]
        )
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("dynatex play: error: unrecognized arguments: --rate-map halves:1,2")
    assert len(err.splitlines()) == 1


# -- a new control touches one place ------------------------------------------------------------
SET = []


class ToyLDSPlayer(lds.LDSPlayer):
    """LDS with one more control, declared once."""

    mode = "lds"
    gain = Control(Range(float, 0.0, 2.0), 1.0, "Toy gain of the frames.")

    @gain.setter
    def gain(self, value: float) -> None:
        SET.append(value)
        self._gain = value


@pytest.fixture
def toy_mode(monkeypatch):
    monkeypatch.setattr(lds, "LDSPlayer", ToyLDSPlayer)
    SET.clear()
    yield ToyLDSPlayer


def test_a_new_control_appears_in_the_cli_the_state_and_the_docs(toy_mode, tmp_path, capsys):
    assert "gain" in controls_of(toy_mode) and player_class("lds") is toy_mode
    # the docs
    assert "\n    gain : a finite number in [0, 2]\n        Toy gain of the frames. Default 1." in toy_mode.__doc__
    # the CLI: --help, and a value that reaches the player
    with pytest.raises(SystemExit):
        main(["play", "--mode", "lds", "--help"])
    assert "--gain GAIN" in capsys.readouterr().out
    db = selftest._db_path()
    out = tmp_path / "f.png"
    assert (
        main(
            [
                "play",
                str(db),
                "--texture",
                selftest.TEXTURE,
                "--backend",
                "numpy",
                "--frames",
                "1",
                "--gain",
                "1.5",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert SET[-1] == 1.5
    with pytest.raises(SystemExit) as exit_:
        main(["play", str(db), "--gain", "3", "-o", str(out)])
    assert exit_.value.code == 2
    assert "argument --gain: expected a finite number in [0, 2], not '3'" in capsys.readouterr().err
    # the state: saved, restored, and a bad value restores nothing
    with open_player(db, selftest.TEXTURE, mode="lds", backend="numpy") as p:
        assert isinstance(p, toy_mode) and p.gain == 1.0
        p.gain = 0.5
        state = p.get_state()
        assert state["gain"] == 0.5
        p.gain = 2.0
        p.set_state(state)
        assert p.gain == 0.5
        bad = dict(state, gain=7.0, speed=-1.0)
        with pytest.raises(ValueError, match=r"gain must be a finite number in \[0, 2\]"):
            p.set_state(bad)
        assert p.gain == 0.5 and p.speed == 1.0


def test_modes_md_is_generated_from_the_declarations():
    path = Path(__file__).resolve().parents[2] / "tools" / "write_modes_doc.py"
    spec = importlib.util.spec_from_file_location("write_modes_doc", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = module.text()
    for mode in MODES:
        cls = player_class(mode)
        section = text.split(f"## `{mode}` ")[1].split("\n## ")[0]
        for c in cls.controls().values():
            assert f"| `{c.name}` |" in section, (mode, c.name)
    assert module.PATH.read_text(encoding="utf-8") == text, (
        "player/MODES.md is stale: run python tools/write_modes_doc.py"
    )
