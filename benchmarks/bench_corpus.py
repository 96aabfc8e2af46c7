"""Corpus-scale analysis: a 2-worker LocalCluster against one-at-a-time, a worker killed
mid-run, and a 1280x720 clip larger than memory learned with --max-memory.

    nice -n 10 python benchmarks/bench_corpus.py corpus [--json out.json]
    nice -n 10 python benchmarks/bench_corpus.py large [--frames 1500] [--max-memory 2GB] [--json out.json]

``corpus`` analyses ../shared/data/clips (and its small_64px folder) with the methods that
suit each clip (METHODS below), first in process, then on a LocalCluster of 2 workers,
then again on 2 workers while one worker is SIGKILLed as soon as some clip's database is
being written; it checks every database, compares the cluster's models with the
sequential ones and reports wall times and the peak resident memory of the process tree
(workers included, sampled from /proc).

``large`` writes a synthetic 1280x720 colour clip of ``--frames`` frames to disk frame by
frame (a ``.npy`` array, which the analyzer reads where it lies), runs
``dynatex analyze --max-memory`` on it in a child process while sampling
the tree's resident memory, and compares the learned LDS with in-memory learns of a
300-frame subsample (subspace angles) and with an out-of-core learn of that subsample.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from _clips import CLIPS

#: The methods that suit each clip of the shared folder (by file-name prefix).
METHODS = {
    "timevarying_": ("lds", "quilt"),
    "pendulum": ("lds", "turnpoints"),
    "fire_flames_720p": ("lds",),
    "steam": ("lds", "mixture", "turnpoints"),
    "": ("lds", "mixture"),
}
PARAMS = {"lds": {"n": 30}, "mixture": {"pca_dim": 30}}


def methods_for(path: str) -> tuple[str, ...]:
    name = os.path.basename(path)
    if os.path.basename(os.path.dirname(path)) == "small_64px":
        return ("lds", "mixture", "tiles")
    for prefix, methods in METHODS.items():
        if name.startswith(prefix):
            return methods
    raise AssertionError("the empty prefix matches every name")


# -- resident memory of a process tree ---------------------------------------------------
def _tree(root: int) -> list[int]:
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(children.get(pid, []))
    return out


def _rss(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


class TreeMemory:
    """Samples the summed resident memory of a process and all its descendants."""

    def __init__(self, root: int, every: float = 0.1) -> None:
        self.root, self.every, self.peak = root, every, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, sum(_rss(p) for p in _tree(self.root)))
            self._stop.wait(self.every)

    def __enter__(self) -> TreeMemory:  # noqa: PYI034
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


# -- comparing databases -------------------------------------------------------------------
def compare_databases(a: str, b: str, texture: str) -> dict[str, dict]:
    """Per method, the largest difference between the two databases' arrays (and the array it is
    in), relative to the largest magnitude of each array, or absolute for arrays whose values
    are all below 1e-3 (round-off-level arrays such as the mixture's decoder offsets);
    0 = identical, integer arrays count 1 when they differ."""
    from dynatex.tiledb import open_db

    out = {}
    with open_db(a) as da, open_db(b) as db:
        da.validate()
        db.validate()
        ta, tb = da.texture(texture), db.texture(texture)
        for method in tb.methods:
            ma, mb = ta.read(method), tb.read(method)
            worst, where = 0.0, ""
            for f in dataclasses.fields(mb):
                x, y = getattr(ma, f.name), getattr(mb, f.name)
                if not isinstance(y, np.ndarray) or y.dtype.kind not in "fiub":
                    continue
                if x.shape != y.shape:
                    diff = float("inf")
                elif y.dtype.kind == "f":
                    scale = max(float(np.abs(y).max(initial=0)), 1e-3)
                    diff = float(np.abs(x.astype(np.float64) - y).max(initial=0)) / scale
                else:
                    diff = 0.0 if np.array_equal(x, y) else 1.0
                if diff > worst:
                    worst, where = diff, f.name
            out[method] = {"max": worst, "array": where}
    return out


# -- corpus ------------------------------------------------------------------------------------
def bench_corpus(workdir: str) -> dict:
    from dynatex.analyzer.corpus import analyze_corpus, connect, format_table

    clips = [str(CLIPS), str(CLIPS / "small_64px")]
    report: dict = {}
    runs = {}
    me = os.getpid()
    for label, scheduler in (("sequential", "none"), ("local-2", "local")):
        out = os.path.join(workdir, label)
        with TreeMemory(me) as mem:
            t = time.perf_counter()
            runs[label] = analyze_corpus(
                clips, out, methods=methods_for, params=PARAMS, scheduler=scheduler, workers=2, progress=False
            )
            wall = time.perf_counter() - t
        report[label] = {
            "wall_s": round(wall, 1),
            "peak_rss_gib": round(mem.peak / 2**30, 2),
            "statuses": _count(runs[label]),
        }
        print(f"== {label}: {wall:.1f} s, peak RSS of the tree {mem.peak / 2**30:.2f} GiB", file=sys.stderr)
        print(format_table(runs[label]), file=sys.stderr)
    report["speedup"] = round(report["sequential"]["wall_s"] / report["local-2"]["wall_s"], 2)
    diffs = {}
    for r_seq, r_par in zip(runs["sequential"], runs["local-2"]):
        if r_seq.status == "ok" and r_par.status == "ok":
            diffs[r_seq.texture] = compare_databases(r_par.database, r_seq.database, r_seq.texture)
    report["cluster_vs_sequential_max_rel_diff"] = diffs

    # A worker SIGKILLed while a database is being written.
    out = os.path.join(workdir, "killed")
    os.makedirs(out, exist_ok=True)
    killed: dict = {}
    with connect("local", 2, 16) as client:
        pids = client.run(os.getpid)

        def killer() -> None:
            deadline = time.time() + 600
            while time.time() < deadline and not killed:
                temps = [n for n in os.listdir(out) if n.endswith(".tmp")]
                busy = client.processing()
                for addr, keys in busy.items():
                    for key in keys:
                        texture = str(key).split("-", 1)[1].rsplit("-", 1)[0]
                        if any(n.startswith(f".{texture}.h5.") for n in temps) and addr in pids:
                            time.sleep(1.0)  # well inside the task
                            os.kill(pids[addr], signal.SIGKILL)
                            killed.update(
                                worker=addr,
                                pid=pids[addr],
                                texture=texture,
                                temp_files=[n for n in temps if n.startswith(f".{texture}.")],
                            )
                            return
                time.sleep(0.05)

        thread = threading.Thread(target=killer, daemon=True)
        thread.start()
        t = time.perf_counter()
        results = analyze_corpus(clips, out, methods=methods_for, params=PARAMS, client=client, progress=False)
        wall = time.perf_counter() - t
        thread.join()
    leftovers = [n for n in os.listdir(out) if n.endswith(".tmp")]
    valid = 0
    for r in results:
        if r.status == "ok":
            compare_databases(r.database, os.path.join(workdir, "sequential", f"{r.texture}.h5"), r.texture)
            valid += 1
    report["killed"] = {
        "wall_s": round(wall, 1),
        "killed": killed,
        "statuses": _count(results),
        "databases_valid": valid,
        "temporaries_left": leftovers,
        "same_statuses_as_sequential": [r.status for r in results] == [r.status for r in runs["sequential"]],
    }
    print(f"== killed run: {wall:.1f} s, killed {killed}", file=sys.stderr)
    print(format_table(results), file=sys.stderr)
    return report


def _count(results) -> dict:
    out: dict = {}
    for r in results:
        out[r.status] = out.get(r.status, 0) + 1
    return out


# -- a clip larger than memory -----------------------------------------------------------------
def write_clip(path: str, frames: int, size=(720, 1280), seed: int = 0) -> None:
    """Two layers of smooth random texture drifting in different directions, plus noise from a
    small bank, written frame by frame to a ``.npy`` array on disk (never all in memory).
    Each frame costs a few copies, so writing is quick even on a busy machine."""
    import cv2

    h, w = size
    rng = np.random.default_rng(seed)

    def smooth(shape, sigma):
        field = cv2.GaussianBlur(rng.normal(0, 1, shape).astype(np.float32), (0, 0), sigma)
        field = (field - field.mean()) / field.std()
        return field

    drift = smooth((h, w + frames), 6)  # moves one pixel per frame to the left
    rise = smooth((h + frames // 2 + 1, w), 12)  # moves one pixel every other frame upwards
    noise = rng.integers(0, 9, (5, h, w, 1), dtype=np.uint8)
    gains = np.array([1.0, 0.8, 0.6], np.float32)
    header = {"descr": "|u1", "fortran_order": False, "shape": (frames, h, w, 3)}
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, header)
        for t in range(frames):
            img = 120 + 40 * drift[:, t : t + w] + 30 * rise[t // 2 : t // 2 + h]
            frame = np.clip(img[..., None] * gains, 0, 246).astype(np.uint8) + noise[t % 5]
            f.write(frame.tobytes())


def subspace_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Principal angles (radians) between the row spaces of two orthonormal-row bases."""
    s = np.linalg.svd(a.astype(np.float64) @ b.astype(np.float64).T, compute_uv=False)
    return np.arccos(np.clip(s, -1, 1))


def bench_large(workdir: str, frames: int, max_memory: str, n: int) -> dict:
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.analyzer.stream import spill_clip
    from dynatex.tiledb import open_db

    clip = os.path.join(workdir, "big.npy")
    t = time.perf_counter()
    write_clip(clip, frames)
    report: dict = {
        "frames": frames,
        "size": "1280x720",
        "clip_bytes": os.path.getsize(clip),
        "float32_clip_gib": round(frames * 1280 * 720 * 3 * 4 / 2**30, 2),
        "write_s": round(time.perf_counter() - t, 1),
        "max_memory": max_memory,
        "n": n,
    }
    db = os.path.join(workdir, "big.h5")
    cmd = [
        sys.executable,
        "-m",
        "dynatex",
        "analyze",
        clip,
        "-o",
        db,
        "--n",
        str(n),
        "--max-memory",
        max_memory,
        "--spill-dir",
        workdir,
        "-q",
    ]
    t = time.perf_counter()
    proc = subprocess.Popen(cmd)
    with TreeMemory(proc.pid, every=0.05) as mem:
        code = proc.wait()
    report.update(
        exit_code=code,
        learn_s=round(time.perf_counter() - t, 1),
        peak_rss_tree_gib=round(mem.peak / 2**30, 3),
        children_maxrss_gib=round(_children_maxrss() / 2**30, 3),
    )
    print(
        f"== large: exit {code}, {report['learn_s']} s, peak tree RSS {report['peak_rss_tree_gib']} GiB",
        file=sys.stderr,
    )
    if code != 0:
        return report
    with open_db(db) as d:
        full = d.texture("big").read("lds")
    report["info"] = {k: full.info[k] for k in ("svd", "column_blocks", "energy_captured", "spectral_radius")}
    # The same 300-frame subsample learned in memory and out of core, and against the full clip.
    step = max(1, frames // 300)
    t = time.perf_counter()
    sub = load_clip(np.load(clip, mmap_mode="r")[::step])
    mem_model = learn_lds(sub, n=n, tone="off")  # a streamed clip is learned on its levels
    report["subsample_in_memory_s"] = round(time.perf_counter() - t, 1)
    del sub
    with spill_clip(clip, folder=workdir, step=step) as disk:
        disk_model = learn_lds(disk, n=n, max_memory=2 << 30)
    k = 16
    report["subsample_streamed_vs_in_memory"] = {
        "basis_max_rel_diff": float(np.abs(disk_model.basis - mem_model.basis).max() / np.abs(mem_model.basis).max()),
        "A_max_abs_diff": float(np.abs(disk_model.A - mem_model.A).max()),
        "max_angle_rad": float(subspace_angles(disk_model.basis, mem_model.basis).max()),
    }
    angles = subspace_angles(full.basis[:k], mem_model.basis[:k])
    report[f"full_vs_subsample_first_{k}_angles_rad"] = {"max": float(angles.max()), "median": float(np.median(angles))}
    report["mean_max_abs_diff"] = float(np.abs(full.mean - mem_model.mean).max())
    return report


def _children_maxrss() -> int:
    import resource

    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("corpus", "large"))
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--max-memory", default="2GB")
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--workdir", default=None, help="where clips and databases go (default: a temporary folder)")
    ap.add_argument("--json", default=None, help="write the report here too")
    args = ap.parse_args()
    if args.what == "corpus" and not CLIPS.is_dir():
        sys.exit(f"{CLIPS} is absent: the corpus benchmark needs the shared clips")
    with tempfile.TemporaryDirectory(prefix="dynatex-bench-", dir=args.workdir) as work:
        report = (
            bench_corpus(work) if args.what == "corpus" else bench_large(work, args.frames, args.max_memory, args.n)
        )
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
