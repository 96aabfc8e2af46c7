"""Several processes writing one database: their commits serialise on the lock beside it and each
carries over what the others committed, so no texture is lost; a waiting writer says so once."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.tiledb import DatabaseWriter, open_db
from dynatex.tiledb.writer import lock_database, lock_path

from ..conftest import wave_clip

pytestmark = pytest.mark.skipif(os.name != "posix", reason="writers are serialised with fcntl.flock (POSIX)")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: A writer of texture argv[2] into argv[1]: opens the database, says so, commits when stdin closes.
CHILD_WRITER = """
import sys
from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.tiledb import DatabaseWriter
from tests.conftest import wave_clip
clip = load_clip(wave_clip(t=20, h=8, w=8, seed=len(sys.argv[2])))
with DatabaseWriter(sys.argv[1]) as w:
    w.put_texture(sys.argv[2], clip.source_info())
    w.put_method(sys.argv[2], "lds", learn_lds(clip, n=3))
    print("ready", flush=True)
    sys.stdin.read()
"""


def _write(db, name: str) -> None:
    clip = load_clip(wave_clip(t=20, h=8, w=8))
    with DatabaseWriter(db) as w:
        w.put_texture(name, clip.source_info())
        w.put_method(name, "lds", learn_lds(clip, n=3))


def _writer(db, name: str) -> subprocess.Popen:
    p = subprocess.Popen(
        [sys.executable, "-c", CHILD_WRITER, str(db), name],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    assert p.stdout.readline().strip() == "ready"
    return p


def _finish(p: subprocess.Popen) -> tuple[int, str]:
    code = p.wait(timeout=120)
    err = p.stderr.read()
    p.stdout.close()
    p.stderr.close()
    return code, err


def test_writers_started_from_the_same_database_keep_every_texture(tmp_path):
    db = tmp_path / "db.h5"
    _write(db, "base")
    names = [f"w{i}" for i in range(4)]
    writers = [_writer(db, n) for n in names]  # all opened "base" and hold their textures
    for p in writers:
        p.stdin.close()  # commit together
    results = [_finish(p) for p in writers]
    assert [code for code, _ in results] == [0] * len(writers), [err for _, err in results]
    with open_db(db) as d:
        d.validate()
        assert d.textures == ("base", *names)
    assert not os.path.exists(lock_path(db))
    assert sorted(os.listdir(tmp_path)) == ["db.h5"]


def test_a_writer_waits_for_the_lock_and_says_so_once(tmp_path):
    db = tmp_path / "db.h5"
    _write(db, "base")
    held = lock_database(db)
    try:
        p = _writer(db, "late")
        p.stdin.close()
        line = p.stderr.readline()  # it cannot commit while the lock is held here
        assert "waiting for another writer" in line and str(db) in line
        assert p.poll() is None
        _write_under(db, "meanwhile", held)
    finally:
        held.release()
    code, rest = _finish(p)
    assert code == 0 and "waiting" not in rest
    with open_db(db) as d:
        assert d.textures == ("base", "late", "meanwhile")


def _write_under(db, name: str, lock) -> None:
    """A commit by the lock's holder, as another writer would make it: a new file renamed in place."""
    other = db.with_name("other.h5")
    _write(other, name)
    with open_db(db) as d, open_db(other) as o, DatabaseWriter(other.with_name("both.h5")) as w:
        for db_ in (d, o):
            for t in db_.textures:
                tex = db_.texture(t)
                w.put_texture(t, tex.source)
                w.put_method(t, "lds", tex.read("lds"))
    os.replace(other.with_name("both.h5"), db)
    os.unlink(other)


def test_a_lock_file_left_by_a_killed_writer_is_taken_over(tmp_path):
    db = tmp_path / "db.h5"
    with open(lock_path(db), "w"):
        pass  # nobody holds it
    _write(db, "first")
    assert not os.path.exists(lock_path(db))
    with open_db(db) as d:
        assert d.textures == ("first",)


def test_concurrent_analyses_and_a_merge_into_one_database_keep_every_texture(tmp_path):
    clips = {}
    for i, name in enumerate(("base", "a", "b", "m1", "m2")):
        clips[name] = tmp_path / f"{name}.npy"
        np.save(clips[name], np.random.default_rng(i).integers(0, 256, (30, 8, 8, 3), dtype=np.uint8))
    db = tmp_path / "db.h5"
    run = [sys.executable, "-m", "dynatex", "analyze", "-q", "--n", "4"]
    subprocess.run([*run, clips["base"], "-o", db], check=True, cwd=ROOT)
    (tmp_path / "corpus").mkdir()
    procs = [
        subprocess.Popen([*run, clips["a"], "-o", db], cwd=ROOT),
        subprocess.Popen([*run, clips["b"], "-o", db], cwd=ROOT),
        subprocess.Popen([*run, clips["m1"], clips["m2"], "-o", tmp_path / "corpus", "--merge", db], cwd=ROOT),
    ]
    assert [p.wait(timeout=300) for p in procs] == [0, 0, 0]
    with open_db(db) as d:
        d.validate()
        assert d.textures == ("a", "b", "base", "m1", "m2")
