"""``dynatex analyze`` over several clips: a folder of databases, a summary, exit code 2 on failures."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.cli import main
from dynatex.tiledb import open_db

from ..conftest import wave_clip


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def clips(tmp_path):
    np.save(tmp_path / "sea.npy", wave_clip(t=30, h=16, w=24, seed=1))
    np.save(tmp_path / "fire.npy", wave_clip(t=30, h=16, w=16, seed=2))
    (tmp_path / "broken.avi").write_bytes(b"RIFF\x00\x00" + b"\x01" * 300)
    return tmp_path


def test_corpus_summary_merge_and_exit_code(tmp_path, clips, capsys):
    out, merged = tmp_path / "dbs", tmp_path / "all.h5"
    code, stdout, err = _run(
        capsys,
        "analyze",
        clips / "sea.npy",
        clips / "fire.npy",
        clips / "broken.avi",
        "-o",
        out,
        "--n",
        "4",
        "--merge",
        merged,
    )
    assert code == 2
    lines = stdout.splitlines()
    assert lines[0].split() == ["clip", "methods", "seconds", "status"]
    assert lines[1].startswith("sea.npy") and lines[1].endswith("ok")
    assert lines[3].startswith("broken.avi") and "failed: " in lines[3] and "broken.avi" in lines[3]
    assert "3 clips: 2 analysed, 0 skipped (database complete), 1 failed" in stdout
    assert "merged 2 textures" in stdout
    assert err.strip().splitlines() == [err.strip()] and err.startswith("dynatex: error: 1 of 3 clips failed")
    with open_db(merged) as db:
        assert sorted(db.textures) == ["fire", "sea"]
    code, stdout, _ = _run(capsys, "analyze", str(clips / "*.npy"), "-o", out, "--n", "4", "-q")
    assert code == 0 and stdout == ""
    code, stdout, _ = _run(capsys, "analyze", clips / "sea.npy", clips / "fire.npy", "-o", out, "--n", "4")
    assert code == 0 and "2 clips: 0 analysed, 2 skipped (database complete), 0 failed" in stdout
    code, stdout, _ = _run(
        capsys,
        "analyze",
        clips / "sea.npy",
        clips / "fire.npy",
        "-o",
        out,
        "--n",
        "4",
        "--overwrite",
        "--merge",
        merged,
    )
    assert code == 0 and "2 clips: 2 analysed, 0 skipped" in stdout


def test_one_clip_with_max_memory_learns_out_of_core(tmp_path, clips, capsys):
    db = tmp_path / "one.h5"
    code, _, err = _run(capsys, "analyze", clips / "sea.npy", "-o", db, "--n", "4", "--max-memory", "1GB")
    assert code == 0, err
    with open_db(db) as d:
        assert d.texture("sea").read("lds").info["svd"] == "gram-streamed"


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--name", "x"], "--name works with one clip only"),
        (["--max-memory", "lots"], "--max-memory: memory size 'lots'"),
        (["--scheduler", "nowhere"], "scheduler must be 'none', 'local' or an address"),
        (["--merge", "/nonexistent-folder/m.h5"], "folder /nonexistent-folder does not exist"),
    ],
)
def test_corpus_usage_errors_are_one_line(tmp_path, clips, capsys, extra, message):
    code, _, err = _run(capsys, "analyze", clips / "sea.npy", clips / "fire.npy", "-o", tmp_path / "dbs", *extra)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("dynatex: error: ") and message in err, err


def test_output_file_with_several_clips_is_refused(tmp_path, clips, capsys):
    (tmp_path / "x.h5").write_bytes(b"")
    code, _, err = _run(capsys, "analyze", clips / "sea.npy", clips / "fire.npy", "-o", tmp_path / "x.h5")
    assert code == 2 and "-o names a folder" in err


def test_an_unreachable_scheduler_is_bad_input_in_one_line(tmp_path, clips, capsys, monkeypatch):
    """A dead scheduler address is the user's input, not a bug: exit 2, one line naming it."""
    pytest.importorskip("distributed", reason="the Dask scheduler needs dynatex[dask]")
    import socket

    import dynatex.analyzer.corpus as corpus

    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setattr(corpus, "SCHEDULER_TIMEOUT_S", 1)
    address = f"tcp://127.0.0.1:{port}"
    code, _, err = _run(capsys, "analyze", clips / "sea.npy", "-o", tmp_path / "dbs", "--scheduler", address)
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith(f"dynatex: error: cannot reach the Dask scheduler at {address}"), err
