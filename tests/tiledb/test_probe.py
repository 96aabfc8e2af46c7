"""The database probe: a file the writer wrote is known safe at once; a changed file is read by a
child process first and then remembered; without an interpreter to run the child, the file is
opened unprobed rather than refused."""

from __future__ import annotations

import h5py
import numpy as np

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.tiledb import DatabaseWriter, TileDB, probe

from ..conftest import wave_clip


def _write(path):
    clip = load_clip(wave_clip(t=12, h=16, w=20))
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", learn_lds(clip, n=4))
    return path


def test_written_files_are_known_and_changed_files_are_probed_then_known(tmp_path, monkeypatch):
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(tmp_path / "cache"))
    path = str(_write(tmp_path / "a.h5"))
    assert probe._passed(probe._identity(path), float("inf"))  # read back whole: safe at any bound
    with h5py.File(path, "r+") as f:  # any change makes it another file
        f.attrs["note"] = np.int64(1)
    key = probe._identity(path)
    assert not probe._passed(key, 1)
    with TileDB(path, max_bytes=2**20) as db:
        assert db.texture("w").read("lds").n == 4
    assert probe._passed(key, 2**20) and probe._passed(key, 1000)
    assert not probe._passed(key, 2**21)  # a larger bound reads more: probed again


def test_without_an_interpreter_the_file_opens_unprobed(tmp_path, monkeypatch):
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(tmp_path / "cache"))
    path = str(_write(tmp_path / "b.h5"))
    with h5py.File(path, "r+") as f:
        f.attrs["note"] = np.int64(2)
    monkeypatch.setenv("DYNATEX_PYTHON", "/usr/bin/my-game")
    assert probe._run_child(path, 1) is None
    with TileDB(path) as db:
        assert "w" in [t.name for t in db]
