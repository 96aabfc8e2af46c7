"""The storage attacks of issue 26, each run through the real commands: what a database that reads
outside itself, or declares more than it holds, does to ``info``, ``play``, ``open_player`` and
``analyze -o``.

    python benchmarks/hostile_storage.py [--only NAME ...] [--bomb-gib 2] [--sparse-gib 4]
                                         [--frames 5000000] [--timeout 90]

Each attack is a small database built here (a turn-point texture with stored frames, or an LDS
texture) changed with one HDF5 feature. Every command runs in its own process under a small
runner process, so its peak resident memory (the command and its probe child, whichever is
larger) is measured; a foreign read is detected by content: frames holding the bytes of
``/etc/passwd`` or of a canary variable put in the command's environment, or a rewritten database
that still holds a link to another file. Prints one line per attack and command: exit status,
seconds, peak MiB, foreign read or not, and the last line of stderr. Runs with whichever dynatex
the interpreter imports, so the same script measures a checkout before and after a change.
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

CANARY = "DYNATEX_CANARY"
#: the runner: runs argv, prints exit status, seconds and the peak RSS of it and its children (KiB)
_RUNNER = (
    "import resource, subprocess, sys, time\n"
    "t = time.perf_counter()\n"
    "try:\n"
    "    code = subprocess.run(sys.argv[2:], timeout=float(sys.argv[1]), stdin=subprocess.DEVNULL).returncode\n"
    "except subprocess.TimeoutExpired:\n"
    "    code = 'timeout'\n"
    "print('RUNNER', code, round(time.perf_counter() - t, 1), "
    "resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr)\n"
)
_PLAYER = (
    "import sys, numpy as np\n"
    "from dynatex.player import open_player\n"
    "with open_player(sys.argv[1], None, mode=sys.argv[2], backend='numpy', seed=1) as p:\n"
    "    np.save(sys.argv[3], np.stack([p.next_frame() for _ in range(int(sys.argv[4]))]))\n"
)


def build(folder: Path) -> dict[str, Path]:
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(pendulum_clip(40, 16)[0])
    tp = folder / "turnpoints.h5"
    with DatabaseWriter(tp, overwrite=True) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
        w.put_method("t", "turnpoints", learn_turnpoints(clip))
    lds = folder / "lds.h5"
    with DatabaseWriter(lds, overwrite=True) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "lds", learn_lds(clip, n=6))
    np.save(folder / "clip.npy", clip.frames)
    return {"turnpoints": tp, "lds": lds}


def attacks(folder: Path, bases: dict[str, Path], args) -> dict[str, tuple[Path, str]]:
    """name -> (database, mode): every attack of the issue's storage rows."""
    out: dict[str, tuple[Path, str]] = {}

    def copy(base: str, name: str) -> Path:
        path = folder / f"{name}.h5"
        shutil.copyfile(bases[base], path)
        return path

    def external(name: str, target: str) -> None:
        path = copy("turnpoints", name)
        with h5py.File(path, "r+") as f:
            ds = f["textures/t/frames"]
            shape, nbytes = ds.shape, ds.id.get_storage_size() and int(np.prod(ds.shape))
            del f["textures/t/frames"]
            f.create_dataset("textures/t/frames", shape=shape, dtype="u1", external=[(target, 0, nbytes)])
        out[name] = (path, "turnpoints")

    external("external-environ", "/proc/self/environ")
    external("external-passwd", "/etc/passwd")
    external("external-relative", os.path.relpath("/etc/passwd", folder))
    fifo = folder / "pipe"
    os.mkfifo(fifo)
    external("external-fifo", str(fifo))

    foreign = folder / "foreign.h5"
    with h5py.File(bases["turnpoints"], "r") as src, h5py.File(foreign, "w") as f:
        frames = src["textures/t/frames"][()]
        f["frames"] = np.full_like(frames, 77)  # another file's pictures: flat grey 77
        src.copy(src["textures/t"], f, name="texture")
        del f["texture/frames"]
        f["texture/frames"] = f["frames"][()]  # the linked texture plays the grey pictures too
        src.copy(src["textures/t/turnpoints"], f, name="method")
    for name, source in (("vds-foreign", str(foreign)), ("vds-missing", str(folder / "missing.h5"))):
        path = copy("turnpoints", name)
        with h5py.File(path, "r+") as f:
            shape = f["textures/t/frames"].shape
            del f["textures/t/frames"]
            layout = h5py.VirtualLayout(shape=shape, dtype="u1")
            layout[...] = h5py.VirtualSource(source, "frames", shape=shape, dtype="u1")
            f.create_virtual_dataset("textures/t/frames", layout)
        out[name] = (path, "turnpoints")
    for name, obj, target in (
        ("extlink-texture", "textures/t", "/texture"),
        ("extlink-method", "textures/t/turnpoints", "/method"),
    ):
        path = copy("turnpoints", name)
        with h5py.File(path, "r+") as f:
            del f[obj]
            f[obj] = h5py.ExternalLink(str(foreign), target)
        out[name] = (path, "turnpoints")

    path = copy("lds", "gzip-bomb")
    n = args.bomb_gib * 2**30 // 8
    with h5py.File(path, "r+") as f:
        del f["textures/t/lds/singular_values"]
        chunk = 2**20
        ds = f.create_dataset(
            "textures/t/lds/singular_values", shape=(n,), dtype="f8", chunks=(chunk,), compression="gzip"
        )
        ds[:chunk] = 0.0
        _, raw = ds.id.read_direct_chunk((0,))
        for start in range(chunk, n, chunk):
            ds.id.write_direct_chunk((start,), raw)
    out["gzip-bomb"] = (path, "lds")

    path = copy("lds", "sparse-bomb")
    with h5py.File(path, "r+") as f:
        del f["textures/t/lds/singular_values"]
        f.create_dataset("textures/t/lds/singular_values", shape=(args.sparse_gib * 2**30 // 8,), dtype="f8")
    out["sparse-bomb"] = (path, "lds")

    path = copy("turnpoints", "many-frames")
    t = args.frames
    with h5py.File(path, "r+") as f:
        tex = f["textures/t"]
        tex["source"].attrs["n_frames"] = t
        tex["turnpoints"].attrs["n_frames"] = t
        frame_shape = tex["frames"].shape[1:]
        del tex["frames"]
        tex.create_dataset("frames", shape=(t, *frame_shape), dtype="u1", chunks=(1, *frame_shape))
        for name in ("sym_raw", "symmetry", "reduced", "p_max"):
            old = tex["turnpoints"][name][()]
            del tex["turnpoints"][name]
            tex["turnpoints"].create_dataset(
                name, data=np.resize(old, t), chunks=(2**16,), compression="gzip", shuffle=True
            )
    out["many-frames"] = (path, "turnpoints")
    path = copy("turnpoints", "many-frames-lzf")  # the same, the frames written as LZF-compressed zeros (89:1)
    with h5py.File(many := folder / "many-frames.h5", "r") as src, h5py.File(path, "w") as f:
        for key, value in src.attrs.items():
            f.attrs[key] = value
        for name in src:
            src.copy(src[name], f, name=name)
        tex = f["textures/t"]
        shape = tex["frames"].shape
        del tex["frames"]
        for name in ("sym_raw", "symmetry", "reduced", "p_max"):  # stored plainly: only the frames compress
            values = tex["turnpoints"][name][()]
            del tex["turnpoints"][name]
            tex["turnpoints"][name] = values
        ds = tex.create_dataset("frames", shape=shape, dtype="u1", chunks=(4096, *shape[1:]), compression="lzf")
        ds[:4096] = 0
        _, raw = ds.id.read_direct_chunk((0, 0, 0, 0))
        for start in range(4096, shape[0], 4096):
            ds.id.write_direct_chunk((start, 0, 0, 0), raw)
    assert many.exists()
    out["many-frames-lzf"] = (path, "turnpoints")
    return out


def run(argv: list[str], env: dict, timeout: float) -> dict:
    proc = subprocess.run(
        [sys.executable, "-c", _RUNNER, str(timeout), *argv],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout + 60,
    )
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    runner = [ln for ln in lines if ln.startswith("RUNNER ")][-1].split()
    rest = [ln for ln in lines if not ln.startswith("RUNNER ")]
    return {
        "exit": runner[1],
        "seconds": float(runner[2]),
        "peak_mib": round(int(runner[3]) / 1024),
        "stderr": rest[-1][:220] if rest else "",
    }


def foreign_bytes(frames: np.ndarray, canary: str) -> bool:
    data = np.ascontiguousarray(frames).tobytes()
    return canary.encode() in data or b"root:" in data or (frames.size > 0 and bool(np.all(frames == 77)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", help="attack names to run (default: all)")
    ap.add_argument("--bomb-gib", type=int, default=2, help="declared GiB of the gzip bomb")
    ap.add_argument("--sparse-gib", type=int, default=4, help="declared GiB of the sparse dataset")
    ap.add_argument("--frames", type=int, default=5_000_000, help="frames the many-frames file declares")
    ap.add_argument("--timeout", type=float, default=90.0, help="seconds a command may take")
    ap.add_argument("--commands", nargs="*", default=["info", "play", "open_player", "analyze"])
    args = ap.parse_args(argv)
    import dynatex

    print(f"dynatex from {Path(dynatex.__file__).parent.parent}", flush=True)
    with tempfile.TemporaryDirectory(prefix="dynatex-hostile-") as tmp:
        folder = Path(tmp)
        bases = build(folder)
        todo = attacks(folder, bases, args)
        canary = secrets.token_hex(12)
        env = dict(os.environ, **{CANARY: canary}, DYNATEX_CACHE_DIR=str(folder / "cache"))
        dyn = [sys.executable, "-m", "dynatex"]
        for name, (path, mode) in todo.items():
            if args.only and name not in args.only:
                continue
            size = os.path.getsize(path)
            for command in args.commands:
                work = folder / f"{name}-{command}"
                work.mkdir()
                foreign = None
                if command == "info":
                    r = run([*dyn, "info", str(path)], env, args.timeout)
                elif command == "play":
                    argv_ = [*dyn, "play", str(path), "--mode", mode, "--backend", "numpy", "--frames", "8"]
                    r = run([*argv_, "-o", str(work / "frame_%04d.png")], env, args.timeout)
                    pngs = sorted(work.glob("*.png"))
                    if pngs:
                        import cv2

                        foreign = foreign_bytes(np.stack([cv2.imread(str(p))[..., ::-1] for p in pngs]), canary)
                elif command == "open_player":
                    npy = work / "frames.npy"
                    r = run([sys.executable, "-c", _PLAYER, str(path), mode, str(npy), "8"], env, args.timeout)
                    if npy.exists():
                        foreign = foreign_bytes(np.load(npy), canary)
                else:  # analyze -o onto the file: is the rewritten database still linked to others?
                    target = work / "target.h5"
                    shutil.copyfile(path, target)
                    before = target.read_bytes()
                    r = run(
                        [
                            *dyn,
                            "analyze",
                            str(folder / "clip.npy"),
                            "-o",
                            str(target),
                            "--name",
                            "new",
                            "--methods",
                            "lds",
                            "--n",
                            "6",
                        ],
                        env,
                        args.timeout,
                    )
                    r["target_unchanged"] = target.read_bytes() == before
                    foreign = None if r["target_unchanged"] else _links_out(target)
                r.update(attack=name, command=command, file_kib=round(size / 1024), foreign=foreign)
                print(json.dumps(r), flush=True)
    return 0


def _links_out(path: Path) -> bool | None:
    """Whether the database at ``path`` holds an external link, external storage or a virtual dataset."""
    found = []
    try:
        with h5py.File(path, "r") as f:

            def visit(name, link):
                if isinstance(link, h5py.ExternalLink):
                    found.append(name)
                elif isinstance(link, h5py.HardLink):
                    obj = f.get(name)
                    if isinstance(obj, h5py.Dataset) and (obj.is_virtual or obj.external):
                        found.append(name)

            f.visititems_links(visit)
    except OSError:
        return None
    return bool(found)


if __name__ == "__main__":
    t0 = time.perf_counter()
    code = main()
    print(f"done in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    sys.exit(code)
