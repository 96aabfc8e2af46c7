"""Bad ``.npy`` clips are bad input: an object array (a pickle), a truncated file and an empty
dimension are one-line ClipErrors naming the file, exit code 2, in memory and with --max-memory."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from dynatex.analyzer.stream import spill_clip
from dynatex.analyzer.video import ClipError, load_clip_path


def _object_array(path) -> None:
    np.save(path, np.array([{"frame": i} for i in range(10)], dtype=object), allow_pickle=True)


def _truncated(path) -> None:
    np.save(path, np.zeros((20, 16, 16, 3), np.uint8))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _empty_dimension(path) -> None:
    np.save(path, np.zeros((10, 0, 5, 3), np.uint8))


BAD = {
    "object": (_object_array, "Python objects"),
    "truncated": (_truncated, "truncated"),
    "empty": (_empty_dimension, "empty dimension"),
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_a_bad_npy_clip_is_a_clip_error(tmp_path, kind):
    make, words = BAD[kind]
    path = tmp_path / f"{kind}.npy"
    make(path)
    with pytest.raises(ClipError, match=words) as err:
        load_clip_path(str(path))
    assert f"{kind}.npy" in str(err.value)
    with pytest.raises(ClipError, match=words):
        spill_clip(str(path), folder=str(tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{kind}.npy"]  # no spill file left


@pytest.mark.parametrize("extra", [[], ["--max-memory", "1GB"]])
@pytest.mark.parametrize("kind", sorted(BAD))
def test_analyze_of_a_bad_npy_clip_is_one_line_and_exit_2(tmp_path, kind, extra):
    make, words = BAD[kind]
    path = tmp_path / f"{kind}.npy"
    make(path)
    r = subprocess.run(
        [sys.executable, "-m", "dynatex", "analyze", str(path), "-o", str(tmp_path / "db.h5"), "-q", *extra],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dynatex: error: ") and words in lines[0], r.stderr


def test_info_escapes_control_characters_read_from_the_file(tmp_path, lds_db, capsys):
    import h5py

    from dynatex.cli import main

    with h5py.File(lds_db, "r+") as f:
        f["textures/waves/source"].attrs["filename"] = "clip\x1b]0;title\x07\x1b[2J\u202e.avi"
    code = main(["info", str(lds_db)])
    out, err = capsys.readouterr()
    assert code in (0, 2)
    text = out + err
    assert not any(c in text for c in "\x1b\x07\u202e"), text
    assert "\\x1b" in text
