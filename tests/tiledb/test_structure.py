"""A database reads only itself, and no more than it holds (issue 26, items 1 and 2).

Before any dataset is read, opening refuses external storage, virtual datasets, external, soft and
user-defined links, with one line naming the object, in the probe child and in this process alike;
the writer refuses such a database, so nothing foreign is ever copied forward. Datasets that declare
more than their storage can hold (sparse, or compressed past a sane ratio) are refused before any
decompression; every other read is bounded by ``max_bytes``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from dynatex.cli import main
from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError, TileDBSizeError, open_db, probe
from dynatex.tiledb.database import DEFAULT_MAX_BYTES

BASIS = "textures/waves/lds/basis"


def _refused(path, objpath: str, match: str) -> str:
    """Open refuses ``path`` naming ``objpath``; the probe child ends in an ordinary error, never a stall or crash."""
    with pytest.raises(TileDBFormatError, match=match) as e:
        open_db(path)
    text = str(e.value)
    assert text.startswith(f"{path}: /{objpath}: ") and "\n" not in text, text
    assert probe._run_child(str(path), os.path.getsize(path)) is None  # exit 1: refused there too, nothing read
    return text


def _replace_external(path, dataset, name):
    with h5py.File(path, "r+") as f:
        arr = f[dataset][()]
        del f[dataset]
        f.create_dataset(dataset, shape=arr.shape, dtype=arr.dtype, external=[(name, 0, arr.nbytes)])
    return arr


@pytest.mark.parametrize("where", ["absolute", "relative", "fifo", "environ"])
def test_external_storage_is_refused_before_any_read(lds_db, tmp_path, where):
    foreign = tmp_path / "foreign.bin"
    if where == "fifo":  # a read would block for ever: refusing it proves nothing was read
        os.mkfifo(foreign)
        name = str(foreign)
    elif where == "environ":
        name = "/proc/self/environ"
    else:
        with h5py.File(lds_db, "r") as f:
            foreign.write_bytes(f[BASIS][()].tobytes())  # the dataset's own bytes: only where they lie is wrong
        name = str(foreign) if where == "absolute" else os.path.relpath(foreign)
    _replace_external(lds_db, BASIS, name)
    _refused(lds_db, BASIS, "keeps its data in external files: a database reads only itself")


@pytest.mark.parametrize("missing", [False, True])
def test_virtual_datasets_are_refused(lds_db, tmp_path, missing):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(lds_db, "r+") as f:
        arr = f[BASIS][()]
        if not missing:
            with h5py.File(foreign, "w") as g:
                g["data"] = arr
        layout = h5py.VirtualLayout(shape=arr.shape, dtype=arr.dtype)
        layout[...] = h5py.VirtualSource(str(foreign), "data", shape=arr.shape, dtype=arr.dtype)
        del f[BASIS]
        f.create_virtual_dataset(BASIS, layout)
    _refused(lds_db, BASIS, "is a virtual dataset")


@pytest.mark.parametrize("obj", ["textures/waves", "textures/waves/lds", "textures/waves/source", BASIS])
def test_external_links_are_refused(lds_db, tmp_path, obj):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(lds_db, "r+") as f:
        with h5py.File(foreign, "w") as g:
            f.copy(f[obj], g, name="copy")  # a faithful copy
        del f[obj]
        f[obj] = h5py.ExternalLink(str(foreign), "/copy")
    _refused(lds_db, obj, "is an external link")


@pytest.mark.parametrize("target", ["/stash", "/nowhere", "/textures/waves"])
def test_soft_links_are_refused(lds_db, target):
    with h5py.File(lds_db, "r+") as f:
        if target == "/stash":
            f.move(BASIS, "/stash")
        else:
            del f[BASIS]
        f[BASIS] = h5py.SoftLink(target)
    _refused(lds_db, BASIS, "is a soft link")


def test_a_second_hard_link_is_refused(lds_db):
    with h5py.File(lds_db, "r+") as f:
        f["textures/waves/lds/again"] = f["textures/waves"]  # a cycle: the texture inside itself
    _refused(lds_db, "textures/waves/lds/again", "second link to an object")


def test_user_defined_links_are_refused(lds_db):
    ctypes = pytest.importorskip("ctypes")
    lib = _hdf5_library(ctypes)
    if lib is None:
        pytest.skip("the HDF5 library h5py loaded cannot be found to register a link class")

    class LinkClass(ctypes.Structure):
        _fields_ = [("version", ctypes.c_int), ("id", ctypes.c_int), ("comment", ctypes.c_char_p)] + [
            (name, ctypes.c_void_p) for name in ("create", "move", "copy", "trav", "delete", "query")
        ]

    trav = ctypes.CFUNCTYPE(ctypes.c_int64, *(ctypes.c_void_p,) * 6)(lambda *a: -1)
    cls = LinkClass(1, 99, b"dynatex test", None, None, None, ctypes.cast(trav, ctypes.c_void_p), None, None)
    if lib.H5Lregister(ctypes.byref(cls)) < 0:
        pytest.skip("this HDF5 refuses to register a link class")
    with h5py.File(lds_db, "r+") as f:
        group = f["textures/waves/lds"]
        lib.H5Lcreate_ud.argtypes = [ctypes.c_int64, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p] + [
            ctypes.c_size_t,
            ctypes.c_int64,
            ctypes.c_int64,
        ]
        assert lib.H5Lcreate_ud(group.id.id, b"custom", 99, b"x", 1, 0, 0) >= 0
    _refused(lds_db, "textures/waves/lds/custom", "is a user-defined link")


def _hdf5_library(ctypes):
    """The HDF5 shared library this process loaded through h5py, or None."""
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "libhdf5" in line and "hl" not in line.split("/")[-1]}
    except OSError:
        return None
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
            if hasattr(lib, "H5Lregister"):
                return lib
        except (OSError, AttributeError):
            continue
    return None


def test_the_writer_refuses_a_database_that_reads_elsewhere(lds_db, tmp_path, synthetic_clip, capsys):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(lds_db, "r+") as f:
        with h5py.File(foreign, "w") as g:
            f.copy(f["textures/waves/lds"], g, name="copy")
        del f["textures/waves/lds"]
        f["textures/waves/lds"] = h5py.ExternalLink(str(foreign), "/copy")
    before = lds_db.read_bytes()
    with pytest.raises(TileDBFormatError, match="/textures/waves/lds: is an external link"):
        DatabaseWriter(lds_db)
    clip = tmp_path / "clip.npy"
    np.save(clip, synthetic_clip)
    code = main(["analyze", str(clip), "-o", str(lds_db), "--name", "new", "--methods", "lds", "--n", "6"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "/textures/waves/lds: is an external link" in err and len(err.splitlines()) == 1
    assert lds_db.read_bytes() == before  # nothing copied forward, nothing rewritten
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.npy", "foreign.h5", "waves.h5"]


@pytest.mark.parametrize("layout", ["chunked", "contiguous"])
def test_sparse_datasets_are_refused(lds_db, layout):
    with h5py.File(lds_db, "r+") as f:
        shape = f[BASIS].shape
        del f[BASIS]
        f.create_dataset(BASIS, shape=shape, dtype="f4", chunks=(1, shape[1]) if layout == "chunked" else None)
    _refused(lds_db, BASIS, "stores none \\(a sparse dataset\\)")


def test_compression_bombs_are_refused_before_decompression(lds_db):
    name = "textures/waves/lds/singular_values"
    n = 2**27  # 1 GiB of float64 zeros in about 1 MB
    with h5py.File(lds_db, "r+") as f:
        del f[name]
        ds = f.create_dataset(name, shape=(n,), dtype="f8", chunks=(2**20,), compression="gzip")
        ds[: 2**20] = 0.0
        _, raw = ds.id.read_direct_chunk((0,))
        for start in range(2**20, n, 2**20):
            ds.id.write_direct_chunk((start,), raw)
    assert os.path.getsize(lds_db) < 2**21
    _refused(lds_db, name, f"declares {n * 8} bytes in \\d+ stored, more than 128:1")


def test_free_axes_are_bounded_by_the_geometry(lds_db):
    # singular values and training states: at most one per source frame (60 here)
    name = "textures/waves/lds/singular_values"
    with h5py.File(lds_db, "r+") as f:
        sv = f[name][()]
        del f[name]
        f[name] = np.linspace(sv[0], 0, 61)
    with pytest.raises(TileDBFormatError, match=f"/{name}: has shape \\(61,\\), expected \\(12..60\\)"):
        open_db(lds_db).texture().read("lds")


def _declared(group: h5py.Group) -> int:
    """Bytes the datasets under ``group`` declare, its subgroups (an lds model's detail) included."""
    sizes = []
    group.visititems(lambda _, obj: sizes.append(obj.nbytes) if isinstance(obj, h5py.Dataset) else None)
    return sum(sizes)


def test_reads_are_bounded_and_the_bound_can_be_raised(lds_db, monkeypatch):
    with h5py.File(lds_db, "r") as f:
        need = _declared(f["textures/waves/lds"])
    with open_db(lds_db, max_bytes=need - 1) as db:
        with pytest.raises(TileDBSizeError, match="/textures/waves/lds: reading the lds model needs .* MiB, more than"):
            db.texture().read("lds")
    with open_db(lds_db, max_bytes=need) as db:
        assert db.texture().read("lds").n == 12
    monkeypatch.setenv("DYNATEX_MAX_READ_BYTES", str(need - 1))
    with TileDB(lds_db) as db, pytest.raises(TileDBSizeError):
        db.texture().read("lds")
    monkeypatch.setenv("DYNATEX_MAX_READ_BYTES", "lots")
    with pytest.raises(ValueError, match="DYNATEX_MAX_READ_BYTES must be a positive number of bytes"):
        open_db(lds_db)
    monkeypatch.delenv("DYNATEX_MAX_READ_BYTES")
    assert open_db(lds_db).max_bytes == DEFAULT_MAX_BYTES


def test_a_whole_frame_store_is_bounded(tmp_path, synthetic_clip):
    from dynatex.analyzer import load_clip

    clip = load_clip(synthetic_clip)
    path = tmp_path / "f.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
    with open_db(path, max_bytes=clip.frames.nbytes - 1) as db:
        store = db.texture().frames()
        assert np.array_equal(store[3], clip.frames[3])  # one frame at a time is fine
        with pytest.raises(TileDBSizeError, match="/textures/t/frames: reading every stored frame needs"):
            store.read()


def test_a_probe_child_out_of_memory_says_so(tmp_path):
    # a legal database whose training states (4 x 3,000,000 float64, 96 MB) a child with little
    # address space cannot hold: the child reports MemoryError as such (exit 3), not as a crash
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds

    from ..conftest import wave_clip

    clip = load_clip(wave_clip(t=12, h=8, w=8))
    path = tmp_path / "big.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", learn_lds(clip, n=4))
    t = 3_000_000
    with h5py.File(path, "r+") as f:
        f["textures/w/source"].attrs["n_frames"] = t
        del f["textures/w/lds/states"]
        f["textures/w/lds/states"] = np.zeros((4, t))
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    baseline = subprocess.run(
        [
            sys.executable,
            "-c",
            "import dynatex.child, dynatex.tiledb.database; print(open('/proc/self/statm').read().split()[0])",
        ],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    vm = int(baseline.stdout.split()[0]) * os.sysconf("SC_PAGE_SIZE")
    limit = vm + 64 * 2**20

    def small():
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    child = [sys.executable, "-m", "dynatex.child", probe.READER, json.dumps([str(path), float("inf")])]
    assert subprocess.run(child, env=env, preexec_fn=small).returncode == 3
    assert subprocess.run(child, env=env).returncode == 0  # with memory to spare it reads


def test_a_probe_child_killed_by_sigkill_is_reported_as_out_of_memory(lds_db, tmp_path, monkeypatch):
    # the kernel's out-of-memory killer sends SIGKILL; an interpreter that receives it stands in
    fake = tmp_path / "python-oom"
    fake.write_text("#!/bin/sh\nkill -9 $$\n")
    fake.chmod(0o755)
    monkeypatch.setenv("DYNATEX_PYTHON", str(fake))
    problem = probe._run_child(str(lds_db), 1)
    assert problem and probe.OUT_OF_MEMORY in problem and "killed by SIGKILL" in problem


def test_the_probe_reads_every_part_a_reader_may_read(tmp_path, synthetic_clip):
    # one texture's model above the bound must not stop the child before the other's
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds

    clip = load_clip(synthetic_clip)
    path = tmp_path / "two.h5"
    with DatabaseWriter(path) as w:
        for name, n in (("big", 12), ("small", 2)):
            w.put_texture(name, clip.source_info())
            w.put_method(name, "lds", learn_lds(clip, n=n))
    with h5py.File(path, "r") as f:
        small = _declared(f["textures/small/lds"])
    with open_db(path, max_bytes=small) as db:
        with pytest.raises(TileDBSizeError, match="/textures/big/lds"):
            db.validate()
        errors = db.validate(keep_going=True)
        assert [e.objpath for e in errors] == ["/textures/big/lds"]
        assert db.texture("small").read("lds").n == 2
