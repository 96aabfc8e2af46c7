"""Cost of the tone map per frame of ``lds`` / ``mixture``: CPU time and frame rate of
``next_frame`` on a texture learned on tone values against the same clip learned on its levels
(``--tone off`` / ``--mix-tone off``: the same basis size), on numpy and OpenCL, for look-ahead
k, in alternating rounds (medians kept: the machine is shared), so that every ratio comes from
one run.

    python benchmarks/bench_tone.py TONED.h5 LEVELS.h5 [--mode lds] [--lookahead 1,8] [--frames 48]
        [--rounds 5] [--device 0:0] [--backends numpy,opencl]
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from bench_lookahead import measure


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("toned")
    ap.add_argument("levels")
    ap.add_argument("--mode", default="lds")
    ap.add_argument("--lookahead", default="1,8")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--device", default=None)
    ap.add_argument("--backends", default="numpy,opencl")
    args = ap.parse_args()
    dbs = {"toned": args.toned, "levels": args.levels}
    runs: dict[tuple, list] = {}
    for _ in range(args.rounds):
        for backend in args.backends.split(","):
            for k in (int(v) for v in args.lookahead.split(",")):
                options = {"lookahead": k} if k > 1 else {}
                for variant, db in dbs.items():
                    cpu, fps, _ = measure(db, args.mode, backend, args.device, options, True, args.frames)
                    runs.setdefault((backend, k, variant), []).append((cpu, fps))
    for backend in args.backends.split(","):
        for k in (int(v) for v in args.lookahead.split(",")):
            t, lv = np.median(runs[(backend, k, "toned")], axis=0), np.median(runs[(backend, k, "levels")], axis=0)
            row = {"backend": backend, "lookahead": k, "cpu_ms_toned": round(t[0], 3), "cpu_ms_levels": round(lv[0], 3)}
            row.update(cpu_ratio=round(t[0] / lv[0], 3), fps_toned=round(t[1], 1), fps_levels=round(lv[1], 1))
            row["fps_ratio"] = round(t[1] / lv[1], 3)
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
