"""``dynatex play --loop``: the wrap discontinuity of every mode, against plain play.

For each database and mode, plays ``--frames`` frames with and without ``--loop`` (numbered
PNGs in a temporary folder) and prints, over the source's median frame step: the wrap (last
frame -> first), and the median and largest of the output's other steps::

    python benchmarks/play_loop_wrap.py steam.h5 fire64.h5 --frames 120
"""

from __future__ import annotations

import argparse
import glob
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np

from dynatex.analyzer.metrics import temporal_discontinuity
from dynatex.player import open_player

MODES = ("tiles", "turnpoints", "evolve", "lds", "mixture")


def play(db: str, mode: str, frames: int, loop: bool, tmp: str) -> np.ndarray:
    out = tempfile.mkdtemp(dir=tmp)
    cmd = [sys.executable, "-m", "dynatex", "play", db, "--mode", mode, "--frames", str(frames), "-o", out]
    subprocess.run([*cmd, *(["--loop"] if loop else [])], check=True, capture_output=True, cwd=tmp)
    files = sorted(glob.glob(os.path.join(out, "*.png")))
    return np.stack([cv2.cvtColor(cv2.imread(f), cv2.COLOR_BGR2RGB) for f in files])


def steps(frames: np.ndarray, source: np.ndarray) -> np.ndarray:
    seq = np.concatenate([frames, frames[:1]])
    return temporal_discontinuity(seq, list(range(1, len(seq))), source=source)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("databases", nargs="+")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--modes", default=",".join(MODES))
    args = ap.parse_args()
    print(f"{'database':28} {'mode':11} {'plain wrap':>10} {'loop wrap':>10} {'median':>7} {'max':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for db in args.databases:
            db = os.path.abspath(db)
            with open_player(db, mode="turnpoints", backend="numpy") as p:
                source = p.texture.frames().read()
            for mode in args.modes.split(","):
                plain = steps(play(db, mode, args.frames, False, tmp), source)
                loop = steps(play(db, mode, args.frames, True, tmp), source)
                print(
                    f"{os.path.basename(db):28} {mode:11} {plain[-1]:10.2f} {loop[-1]:10.2f} "
                    f"{np.median(loop[:-1]):7.2f} {loop[:-1].max():7.2f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
