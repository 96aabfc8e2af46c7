"""Cost of the colour set (the ``gamut`` part) per frame of ``lds`` / ``mixture``: CPU time and
frame rate of ``next_frame`` on a database with the part, on a copy without it and on a copy
with the clip's set alone (no ``gamut/local``: ``global``), on numpy and OpenCL, for look-ahead
k, in alternating rounds (medians kept: the machine is shared), so that every ratio comes from
one run. The detail plays in all.

    python benchmarks/bench_gamut.py DB.h5 [--mode lds] [--lookahead 1,8] [--frames 48]
        [--rounds 5] [--device 0:0] [--backends numpy,opencl]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile

import h5py
import numpy as np
from bench_lookahead import measure


def without_gamut(db: str, folder: str, part: str = "gamut") -> str:
    """A copy of ``db`` whose textures' lds and mixture models have no ``part`` (``gamut``, or
    ``gamut/local``)."""
    out = os.path.join(folder, f"without_{part.replace('/', '_')}.h5")
    shutil.copy(db, out)
    with h5py.File(out, "a") as f:
        for texture in f["textures"].values():
            for method in ("lds", "mixture"):
                if method in texture and part in texture[method]:
                    del texture[method][part]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("db")
    ap.add_argument("--mode", default="lds")
    ap.add_argument("--lookahead", default="1,8")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--device", default=None)
    ap.add_argument("--backends", default="numpy,opencl")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="dynatex-gamut-") as tmp:
        dbs = {
            "with": args.db,
            "without": without_gamut(args.db, tmp),
            "global": without_gamut(args.db, tmp, "gamut/local"),
        }
        runs: dict[tuple, list] = {}
        for _ in range(args.rounds):
            for backend in args.backends.split(","):
                for k in (int(v) for v in args.lookahead.split(",")):
                    options = {"lookahead": k} if k > 1 else {}
                    for variant, db in dbs.items():
                        cpu, fps, _ = measure(db, args.mode, backend, args.device, options, True, args.frames)
                        runs.setdefault((backend, k, variant), []).append((cpu, fps))
    for (backend, k, variant), vals in sorted(runs.items()):
        if variant != "with":
            continue
        w, wo = np.median(vals, axis=0), np.median(runs[(backend, k, "without")], axis=0)
        gl = np.median(runs[(backend, k, "global")], axis=0)
        print(
            json.dumps(
                {
                    "backend": backend,
                    "lookahead": k,
                    "cpu_ms_with": round(w[0], 3),
                    "cpu_ms_without": round(wo[0], 3),
                    "cpu_ms_global": round(gl[0], 3),
                    "cpu_ratio": round(w[0] / wo[0], 3),
                    "cpu_ratio_to_global": round(w[0] / gl[0], 3),
                    "fps_with": round(w[1], 1),
                    "fps_without": round(wo[1], 1),
                    "fps_global": round(gl[1], 1),
                    "fps_ratio": round(w[1] / wo[1], 3),
                    "fps_ratio_to_global": round(w[1] / gl[1], 3),
                }
            )
        )


if __name__ == "__main__":
    main()
