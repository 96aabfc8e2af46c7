"""The corpus runner: many clips, one database each, failures kept apart, re-runs skipped, merge."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from dynatex.analyzer import analyze_corpus, format_table
from dynatex.analyzer.corpus import (
    _from_disk,
    blas_threads,
    connect,
    find_clips,
)
from dynatex.analyzer.stream import spill_clip
from dynatex.tiledb import open_db
from dynatex.tiledb.schema import texture_names_from_paths
from dynatex.tiledb.writer import remove_stale_temp_files

from ..conftest import wave_clip
from .subspace import assert_same_lds

#: turn-point settings that find turns in the short synthetic clips
TURNS = {"min_symmetry": 0.0, "r": 2}


def _avi(path, frames) -> str:
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 25, (frames.shape[2], frames.shape[1]))
    for f in frames:
        out.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    out.release()
    return str(path)


def _mp4(path, frames) -> str:
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25, (frames.shape[2], frames.shape[1]))
    for f in frames:
        out.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    out.release()
    return str(path)


@pytest.fixture
def corpus(tmp_path):
    """Three good clips (two arrays, one FFV1 video) and two bad ones (a truncated MP4, a text file)."""
    src = tmp_path / "clips"
    src.mkdir()
    np.save(src / "a.npy", wave_clip(t=30, h=16, w=24, seed=1))
    np.save(src / "b.npy", wave_clip(t=36, h=16, w=20, seed=2))
    _avi(src / "c.avi", wave_clip(t=30, h=16, w=16, seed=3))
    _mp4(tmp_path / "whole.mp4", wave_clip(t=30, h=16, w=16, seed=4))
    data = (tmp_path / "whole.mp4").read_bytes()
    (src / "d_truncated.mp4").write_bytes(data[: len(data) // 2])
    (src / "e_notes.avi").write_text("not a video at all\n" * 50)
    (src / "README.md").write_text("not a clip")
    return src


def _by_name(results):
    return {r.texture: r for r in results}


def test_find_clips_folders_globs_and_lists(tmp_path, corpus):
    clips = find_clips([corpus])
    assert [os.path.basename(c) for c in clips] == ["a.npy", "b.npy", "c.avi", "d_truncated.mp4", "e_notes.avi"]
    assert find_clips([str(corpus / "*.npy"), str(corpus / "a.npy")]) == [str(corpus / "a.npy"), str(corpus / "b.npy")]
    (tmp_path / "list.txt").write_text("# two clips\nclips/c.avi\n\nclips/b.npy  # and a comment\n")
    assert find_clips([tmp_path / "list.txt"]) == [str(tmp_path / "clips" / "c.avi"), str(tmp_path / "clips" / "b.npy")]
    frames = tmp_path / "frames"
    frames.mkdir()
    assert find_clips([frames]) == [str(frames)]  # a folder without clips is a folder of images
    with pytest.raises(FileNotFoundError, match="missing.avi: no such clip"):
        find_clips([corpus / "missing.avi"])
    with pytest.raises(FileNotFoundError, match="matches no clip"):
        find_clips([str(corpus / "*.mkv")])
    (tmp_path / "bad.txt").write_text("clips/a.npy\nclips/nope.avi\n")
    with pytest.raises(FileNotFoundError, match=r"bad\.txt:2: .*nope\.avi"):
        find_clips([tmp_path / "bad.txt"])


def test_texture_names_are_valid_and_distinct():
    """The corpus names textures by the one rule of the format (an analysis of one clip uses it too)."""
    names = texture_names_from_paths(["x/sea wave.avi", "y/sea wave.avi", "z/über.npy", "w/.x.npy"])
    assert names == ["sea wave", "sea wave_2", "über", "x"]


def test_corpus_in_process_fails_bad_clips_keeps_others_and_skips_on_rerun(tmp_path, corpus):
    out = tmp_path / "dbs"
    results = analyze_corpus([corpus], out, methods=("lds",), params={"lds": {"n": 6}}, progress=False)
    rows = _by_name(results)
    assert [r.status for r in results] == ["ok", "ok", "ok", "failed", "failed"]
    assert "d_truncated.mp4" in rows["d_truncated"].reason and "\n" not in rows["d_truncated"].reason
    assert "e_notes.avi" in rows["e_notes"].reason
    for name in ("a", "b", "c"):
        with open_db(out / f"{name}.h5") as db:
            db.validate()
            assert db.textures == (name,) and db.texture(name).read("lds").n == 6
    assert sorted(os.listdir(out)) == ["a.h5", "b.h5", "c.h5"]  # nothing for the failed clips, no temporaries
    table = format_table(results)
    assert "5 clips: 3 analysed, 0 skipped (database complete), 2 failed" in table
    assert "failed: " in table

    stamp = (out / "a.h5").stat().st_mtime_ns
    again = analyze_corpus([corpus], out, methods=("lds",), params={"lds": {"n": 6}}, progress=False)
    assert [r.status for r in again] == ["skipped", "skipped", "skipped", "failed", "failed"]
    assert (out / "a.h5").stat().st_mtime_ns == stamp

    np.save(corpus / "a.npy", wave_clip(t=30, h=16, w=24, seed=9))  # new content: a new hash
    third = _by_name(
        analyze_corpus(
            [corpus / "a.npy", corpus / "b.npy"], out, methods=("lds",), params={"lds": {"n": 6}}, progress=False
        )
    )
    assert third["a"].status == "ok" and third["b"].status == "skipped"
    more = _by_name(
        analyze_corpus(
            [corpus / "b.npy"],
            out,
            methods=("lds", "turnpoints"),
            params={"lds": {"n": 6}, "turnpoints": TURNS},
            progress=False,
        )
    )
    assert more["b"].status == "ok"  # a method missing: re-analysed


def test_merge_gathers_every_good_texture(tmp_path, corpus):
    out = tmp_path / "dbs"
    merged = tmp_path / "all.h5"
    results = analyze_corpus(
        [corpus / "a.npy", corpus / "c.avi", corpus / "e_notes.avi"],
        out,
        methods=("lds", "turnpoints"),
        params={"lds": {"n": 4}, "turnpoints": TURNS},
        merge=merged,
        progress=False,
    )
    assert [r.status for r in results] == ["ok", "ok", "failed"]
    with open_db(merged) as db, open_db(out / "c.h5") as one:
        db.validate()
        assert db.textures == ("a", "c")
        assert db.texture("c").methods == ("lds", "turnpoints")
        np.testing.assert_array_equal(db.texture("c").read("lds").basis, one.texture("c").read("lds").basis)
        np.testing.assert_array_equal(db.texture("c").frames().read(), one.texture("c").frames().read())
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".tmp")]


def test_stale_temporaries_of_a_killed_writer_are_removed(tmp_path, corpus):
    out = tmp_path / "dbs"
    out.mkdir()
    stale = out / ".a.h5.x1y2z3w4.tmp"
    stale.write_bytes(b"half an HDF5 file")
    other = out / ".b.h5.keep.tmp"
    other.write_bytes(b"")
    assert remove_stale_temp_files(str(out / "a.h5")) == [str(stale)]
    assert not stale.exists() and other.exists()


def test_max_memory_streams_lds_and_refuses_in_memory_methods_that_do_not_fit(tmp_path, corpus):
    out = tmp_path / "dbs"
    ref = analyze_corpus(
        [corpus / "c.avi"], tmp_path / "ref", methods=("lds",), params={"lds": {"n": 5}}, progress=False
    )
    assert ref[0].status == "ok"
    streamed = analyze_corpus(
        [corpus / "c.avi"],
        out,
        methods=("lds",),
        params={"lds": {"n": 5}},
        max_memory="1GB",
        spill_dir=str(tmp_path),
        progress=False,
    )
    assert streamed[0].status == "ok"
    with open_db(out / "c.h5") as db, open_db(tmp_path / "ref" / "c.h5") as one:
        a, b = db.texture("c").read("lds"), one.texture("c").read("lds")
        assert a.info["svd"] == "gram-streamed"
        assert_same_lds(a, b, tol=1e-4)
        assert db.texture("c").source == one.texture("c").source
    assert not [n for n in os.listdir(tmp_path) if n.startswith("dynatex-spill-")]  # spill files removed
    small = analyze_corpus(
        [corpus / "c.avi"],
        tmp_path / "small",
        methods=("lds", "turnpoints"),
        params={"lds": {"n": 5}, "turnpoints": TURNS},
        max_memory=400 << 20,
        progress=False,
    )
    assert small[0].status == "ok"
    tiny = analyze_corpus(
        [corpus / "c.avi"],
        tmp_path / "tiny",
        methods=("lds",),
        params={"lds": {"n": 5}},
        max_memory="64MB",
        progress=False,
    )
    assert tiny[0].status == "failed" and "max_memory 0.06 GiB is too small for c.avi" in tiny[0].reason
    with (
        spill_clip(corpus / "c.avi") as disk,
        pytest.raises(MemoryError, match="method tiles needs the clip in memory .* only lds, mixture"),
    ):
        _from_disk(disk, "tiles", disk.nbytes)


def _blas_threads() -> str:
    return os.environ["OPENBLAS_NUM_THREADS"]


def test_local_cluster_gives_the_sequential_models(tmp_path, corpus):
    pytest.importorskip("distributed", reason="the dask extra is not installed")
    clips = [corpus / "a.npy", corpus / "b.npy", corpus / "c.avi", corpus / "e_notes.avi"]
    seq = analyze_corpus(clips, tmp_path / "seq", methods=("lds",), params={"lds": {"n": 6}}, progress=False)
    with connect("local", 2, len(clips)) as client:
        par = analyze_corpus(
            clips, tmp_path / "par", methods=("lds",), params={"lds": {"n": 6}}, client=client, progress=False
        )
        threads = client.run(_blas_threads)
    assert sorted(threads.values()) == [str(blas_threads(2))] * 2 == [str(max(1, os.cpu_count() // 2))] * 2
    assert [r.status for r in par] == [r.status for r in seq] == ["ok", "ok", "ok", "failed"]
    assert par[3].reason == seq[3].reason
    assert {r.worker for r in par[:3]} <= {0, 1, "0", "1"} and all(r.worker == "" for r in seq)
    for r in par[:3]:
        with open_db(r.database) as db, open_db(tmp_path / "seq" / f"{r.texture}.h5") as one:
            np.testing.assert_allclose(
                db.texture(r.texture).read("lds").A, one.texture(r.texture).read("lds").A, atol=1e-6
            )
