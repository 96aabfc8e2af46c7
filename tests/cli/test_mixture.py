"""``dynatex analyze --methods mixture`` and ``dynatex play --mode mixture``."""

from __future__ import annotations

import numpy as np

from dynatex.cli import main
from dynatex.tiledb import TileDB

from ..conftest import wave_clip


def test_analyze_then_play(tmp_path, capsys):
    np.save(tmp_path / "w.npy", wave_clip(60))
    db = tmp_path / "w.h5"
    rc = main(
        [
            "analyze",
            str(tmp_path / "w.npy"),
            "-o",
            str(db),
            "--methods",
            "mixture,lds",
            "--n",
            "8",
            "--mix-components",
            "2",
            "--mix-dim",
            "3",
            "--mix-pca-dim",
            "12",
            "--mix-neighbors",
            "6",
            "--mix-pmax",
            "3",
        ]
    )
    assert rc == 0
    err = capsys.readouterr().err
    assert "mixture: S=2 d=3 D=3, switching, AR(2) per component" in err
    with TileDB(db) as d:
        assert set(d.texture("w").methods) == {"lds", "mixture"}
    out = tmp_path / "frames"
    rc = main(
        [
            "play",
            str(db),
            "--mode",
            "mixture",
            "--frames",
            "4",
            "--intensity",
            "0.5",
            "-o",
            str(out) + "/",
        ]
    )
    assert rc == 0
    assert len(list(out.glob("*.png"))) == 4
    capsys.readouterr()
    # draws has no effect on the switching process this analysis stores: refused in one line
    rc = main(["play", str(db), "--mode", "mixture", "--frames", "2", "--draws", "4", "-o", str(tmp_path / "x") + "/"])
    err = capsys.readouterr().err
    assert rc == 2 and "does not offer the control draws" in err and len(err.strip().splitlines()) == 1


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    np.save(tmp_path / "w.npy", wave_clip(20))
    db = tmp_path / "w.h5"
    rc = main(
        [
            "analyze",
            str(tmp_path / "w.npy"),
            "-o",
            str(db),
            "--methods",
            "mixture",
            "--mix-components",
            "5",
            "--mix-dim",
            "4",
        ]
    )
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "components=5 with dim=4 needs more than" in err and "\n" not in err
    assert not db.exists()
    np.save(tmp_path / "c.npy", np.full((60, 8, 8, 3), 9, np.uint8))
    rc = main(["analyze", str(tmp_path / "c.npy"), "-o", str(db), "--methods", "mixture"])
    assert rc == 2 and "clip is constant" in capsys.readouterr().err
    assert not db.exists()
