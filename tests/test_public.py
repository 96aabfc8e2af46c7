"""What ``import dynatex`` offers a newcomer: the names the README lists, loaded on first use so
that a game importing dynatex pays for no analyzer; the texture's own mode when none is named."""

from __future__ import annotations

import re
import subprocess
import sys
from importlib import resources
from pathlib import Path

import h5py
import pytest

import dynatex
from dynatex.errors import ArgumentTypeError, DynatexError
from dynatex.player import UnknownControlError, open_player
from dynatex.player.modes import MODE_METHOD, MODES, default_mode, describe, resolve_mode
from dynatex.tiledb import MethodNotFoundError, TileDBFormatError, open_db
from dynatex.tiledb.database import PLAYER_MODES

README = Path(__file__).resolve().parents[1] / "README.md"
SELFTEST = str(resources.files("dynatex.player").joinpath("selftest.h5"))


def test_dir_is_the_public_surface_the_readme_lists():
    public = sorted(n for n in dir(dynatex) if not n.startswith("_"))
    assert public == sorted(n for n in dynatex.__all__ if n != "__version__")
    assert "annotations" not in dir(dynatex) and "__version__" in dir(dynatex)
    text = README.read_text(encoding="utf-8")
    section = text.split("### What `import dynatex` gives", 1)[1].split("\n#", 1)[0]
    listed = set(re.findall(r"`dynatex\.([A-Za-z]\w*)`", section))
    assert listed == set(public), listed ^ set(public)
    for name in public:
        assert getattr(dynatex, name) is not None
    assert issubclass(dynatex.UnknownControlError, dynatex.DynatexError)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        dynatex.nope  # noqa: B018


def test_import_dynatex_is_light_and_the_player_needs_no_analyzer():
    code = (
        "import sys, dynatex\n"
        "heavy = lambda: sorted(m for m in sys.modules if m.split('.')[0] in ('cv2', 'scipy', 'dask', 'matplotlib')"
        " or m.startswith(('dynatex.analyzer', 'dynatex.player', 'dynatex.tiledb')))\n"
        "print(heavy())\n"
        "dynatex.open_player, dynatex.describe, dynatex.DynatexError\n"
        "print(heavy())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.splitlines()
    assert out[0] == "[]", out[0]
    assert "dynatex.player" in out[1] and "cv2" not in out[1] and "scipy" not in out[1], out[1]
    assert "dynatex.analyzer" not in out[1] and "dask" not in out[1], out[1]


def test_describe_lists_textures_modes_and_controls_with_ranges():
    d = dynatex.describe(SELFTEST)
    tex = d["textures"]["selftest"]
    assert tex["modes"] == list(PLAYER_MODES) and tex["default_mode"] == "lds"
    speeds = {m: d["modes"][m]["controls"]["speed"]["rule"] for m in ("lds", "tiles", "turnpoints", "evolve")}
    assert speeds == {
        "lds": "a finite number in [-3, 3]",
        "tiles": "a finite number in [-4, 4]",
        "turnpoints": "a finite number in [0, 4]",
        "evolve": "a finite number in [-16, 16]",
    }
    assert d["modes"]["evolve"]["method"] == "quilt" and d["modes"]["lds"]["controls"]["speed"]["default"] == "1"


def test_the_tiledb_and_player_know_the_same_modes():
    assert set(PLAYER_MODES) == set(MODES) == set(MODE_METHOD)
    assert resolve_mode("quilt") == "evolve"  # the mode that plays a quilt analysis, by its method's name


def test_every_mode_declares_its_method_and_how_it_closes_a_loop():
    """A mode class says which analysis it plays (the database layer's MODE_METHOD agrees) and,
    when its capabilities say it has a loop of its own, closes that loop itself."""
    from dynatex.player import player_class
    from dynatex.player.base import Player

    for mode in MODES:
        cls = player_class(mode)
        assert cls.method == MODE_METHOD[mode], mode
        assert (cls._native_loop is not Player._native_loop) == cls.capabilities.native_loop, mode


def _one_method_db(tmp_path, method: str, default: str | None = None) -> Path:
    """The self-test database with only ``method`` kept (and a ``default_mode`` attribute)."""
    path = tmp_path / f"{method}.h5"
    path.write_bytes(Path(SELFTEST).read_bytes())
    with h5py.File(path, "r+") as f:
        tex = f["textures/selftest"]
        for name in list(tex):
            if name not in (method, "source", "frames"):
                del tex[name]
        if default is not None:
            tex.attrs["default_mode"] = default
    return path


@pytest.mark.parametrize(("method", "mode"), [("tiles", "tiles"), ("quilt", "evolve"), ("turnpoints", "turnpoints")])
def test_a_texture_with_one_method_plays_in_its_mode_without_naming_it(tmp_path, method, mode):
    db = _one_method_db(tmp_path, method)
    with open_player(db, backend="numpy") as p:
        assert p.mode == mode and p.next_frame().std() > 0


def test_several_methods_play_in_the_documented_order_unless_the_texture_names_its_mode(tmp_path):
    with open_db(SELFTEST) as db:
        assert default_mode(db.texture()) == "lds" and db.texture().default_mode is None
    path = tmp_path / "chosen.h5"
    path.write_bytes(Path(SELFTEST).read_bytes())
    with h5py.File(path, "r+") as f:
        f["textures/selftest"].attrs["default_mode"] = "tiles"
    with open_player(path, backend="numpy") as p:
        assert p.mode == "tiles"
    assert describe(path)["textures"]["selftest"]["modes"][0] == "tiles"


@pytest.mark.parametrize(
    ("value", "problem"),
    [("water", r"'water' is not a player mode"), ("lds", r"mode 'lds' plays 'lds' data, which the texture lacks")],
)
def test_a_bad_default_mode_attribute_is_a_format_error(tmp_path, value, problem):
    db = _one_method_db(tmp_path, "tiles", default=value)
    with pytest.raises(TileDBFormatError, match=r"/textures/selftest@default_mode: " + problem):
        open_db(db)


def test_a_missing_method_names_the_modes_the_texture_plays_before_a_new_analysis(tmp_path):
    db = _one_method_db(tmp_path, "tiles")
    with pytest.raises(MethodNotFoundError) as info:
        open_player(db, mode="lds", backend="numpy")
    message = str(info.value)
    assert message.index("--mode tiles") < message.index("dynatex analyze"), message


# -- mistakes caught ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("mode", "name", "hint"), [("lds", "sped", "did you mean 'speed'"), ("lds", "draws", "")])
def test_setting_a_control_a_player_does_not_have_is_an_attribute_error(mode, name, hint):
    with open_player(SELFTEST, mode=mode, backend="numpy") as p:
        with pytest.raises(AttributeError, match=f"no control '{name}': {hint}.*its controls are ") as info:
            setattr(p, name, 2)
        assert str(info.value).endswith("its controls are " + ", ".join(p.controls()))
        assert not hasattr(p, name)
        p.speed = 2  # a real control still works
        assert p.speed == 2.0


def test_intensity_on_turnpoints_is_refused_naming_its_controls():
    with open_player(SELFTEST, mode="turnpoints", backend="numpy") as p:
        with pytest.raises(UnknownControlError, match="its controls are speed, crossfade, increment"):
            p.intensity = 2


@pytest.mark.parametrize(
    ("mode", "options", "match"),
    [
        ("lds", {"size": (24, 40)}, r"takes no option 'size' \(it plays at the size its model fixes; modes of any"),
        ("lds", {"sped": 2}, r"did you mean the control 'speed'\?"),
        ("mixture", {"speed": 0.5}, r"no option 'speed'.*its options: texture, backend, device, format, seed"),
    ],
)
def test_an_option_a_mode_does_not_take_is_the_librarys_argument_error(mode, options, match):
    with pytest.raises(ArgumentTypeError, match=match) as info:
        open_player(SELFTEST, mode=mode, backend="numpy", **options)
    assert isinstance(info.value, TypeError) and isinstance(info.value, DynatexError)


def test_a_size_the_evolve_quilt_cannot_produce_is_a_clear_error():
    with pytest.raises(DynatexError, match=r"does not fit the stored quilt"):
        open_player(SELFTEST, mode="evolve", backend="numpy", size=(1080, 1920))


def test_every_public_name_is_loaded_lazily_from_one_table():
    assert set(dynatex.__all__) - {"__version__"} == set(dynatex._LAZY)
