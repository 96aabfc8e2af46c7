"""The non-stationary warning: a clip that is not one texture all over (a single moving object)
gets a stationarity figure below the threshold, and analysis and ``dynatex info`` say so."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.tiles import STATIONARITY_WARN, stationarity, stationarity_warning
from dynatex.cli import main

from .test_tiles import _stochastic


def moving_object(t: int = 60, h: int = 72, w: int = 88) -> np.ndarray:
    """A red disc moving over a plain grey background."""
    frames = np.full((t, h, w, 3), 90, np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    for k in range(t):
        cy, cx = h / 2 + 0.3 * h * np.sin(k / 8), 10 + k * (w - 20) / t
        frames[k][(yy - cy) ** 2 + (xx - cx) ** 2 < (h / 8) ** 2] = (230, 60, 40)
    return frames


def test_a_single_object_is_not_stationary_and_a_texture_is():
    obj, details = stationarity(moving_object())
    assert obj < STATIONARITY_WARN and details["worst"] in ("brightness", "contrast", "activity")
    tex, _ = stationarity(_stochastic(t=40))
    assert tex > 0.6
    assert stationarity_warning({"stationarity": obj, "stationarity_worst": details["worst"]}).startswith(
        "the clip is not one texture all over"
    )
    assert stationarity_warning({"stationarity": tex}) is None


@pytest.mark.clips
@pytest.mark.parametrize("name", ["grass_straw_wind_dyntex.avi", "water_sea_waves_dyntex.avi"])
def test_grass_and_sea_are_stationary(clips_dir, name):
    figure, _ = stationarity(load_clip(clips_dir / name, stop=100).frames)
    assert figure > STATIONARITY_WARN + 0.1, figure


def test_analyze_warns_and_info_shows_it(tmp_path, capsys):
    np.save(tmp_path / "obj.npy", moving_object())
    db = tmp_path / "o.h5"
    code = main(
        [
            "analyze",
            str(tmp_path / "obj.npy"),
            "-o",
            str(db),
            "--methods",
            "tiles",
            "--tiles-min-loop",
            "16",
            "--tiles-period",
            "144x144",
        ]
    )
    _, err = capsys.readouterr()
    assert code == 0
    warnings = [ln for ln in err.splitlines() if "warning" in ln]
    assert len(warnings) == 1 and "not one texture all over (stationarity 0." in warnings[0]
    assert main(["info", str(db), "--json"]) == 0
    info = json.loads(capsys.readouterr()[0])["textures"]["obj"]["methods"]["tiles"]
    assert info["stationarity"] < STATIONARITY_WARN and "not one texture all over" in info["warning"]
    assert main(["info", str(db)]) == 0
    assert "not one texture all over" in capsys.readouterr()[0]
    # a texture: no warning
    np.save(tmp_path / "tex.npy", _stochastic(t=40))
    code = main(
        [
            "analyze",
            str(tmp_path / "tex.npy"),
            "-o",
            str(tmp_path / "t.h5"),
            "--methods",
            "tiles",
            "--tiles-min-loop",
            "16",
            "--tiles-period",
            "144x144",
        ]
    )
    assert code == 0 and "warning" not in capsys.readouterr()[1]
