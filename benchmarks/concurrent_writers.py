"""Concurrent writers of one database: textures lost over repeated trials.

Each trial seeds ``db.h5`` with one texture, then starts at once two ``dynatex analyze CLIP -o db.h5``
and one ``dynatex analyze A B -o corpus/ --merge db.h5`` (two textures), and counts the textures of
the final database against the five expected. Run with another interpreter to measure another
checkout: ``python benchmarks/concurrent_writers.py --python /work/main/.venv/bin/python``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import h5py
import numpy as np


def _clip(path: str, seed: int) -> str:
    rng = np.random.default_rng(seed)
    frames = rng.integers(0, 256, (60, 16, 16, 3), dtype=np.uint8)
    np.save(path, frames)
    return path


def trial(python: str, folder: str) -> tuple[int, list[int]]:
    clips = {n: _clip(os.path.join(folder, f"{n}.npy"), i) for i, n in enumerate(("base", "a", "b", "m1", "m2"))}
    db = os.path.join(folder, "db.h5")
    run = [python, "-m", "dynatex", "analyze", "-q"]  # run in ``folder``: the cwd must not shadow the package
    subprocess.run([*run, clips["base"], "-o", db], check=True, capture_output=True, cwd=folder)
    os.mkdir(os.path.join(folder, "corpus"))
    procs = [
        subprocess.Popen([*run, clips["a"], "-o", db], stderr=subprocess.PIPE, cwd=folder),
        subprocess.Popen([*run, clips["b"], "-o", db], stderr=subprocess.PIPE, cwd=folder),
        subprocess.Popen(
            [*run, clips["m1"], clips["m2"], "-o", os.path.join(folder, "corpus"), "--merge", db],
            stderr=subprocess.PIPE,
            cwd=folder,
        ),
    ]
    codes = [p.wait() for p in procs]
    for p in procs:
        p.stderr.close()
    with h5py.File(db, "r") as f:
        found = set(f["textures"].keys())
    return len({"base", "a", "b", "m1", "m2"} - found), codes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable, help="interpreter whose dynatex runs the writers")
    parser.add_argument("--trials", type=int, default=20)
    args = parser.parse_args(argv)
    lost_total, bad_trials = 0, 0
    for i in range(args.trials):
        with tempfile.TemporaryDirectory() as folder:
            lost, codes = trial(args.python, folder)
        lost_total += lost
        bad_trials += lost > 0
        print(f"trial {i + 1}: {lost} textures lost, exit codes {codes}", flush=True)
    print(f"{args.trials} trials: {lost_total} textures lost, in {bad_trials} trials")
    return 0


if __name__ == "__main__":
    sys.exit(main())
