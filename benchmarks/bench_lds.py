"""LDS benchmark: player frame rate vs numpy and the roofline, and analysis time.

    python benchmarks/bench_lds.py [--frames 200] [--json]

Player: synthetic n=50 textures at 352x288 and 1280x720, float32 and float16 bases
(the cost depends only on sizes). Analysis: learning from a 250-frame 352x288 colour
clip (the real sea-waves clip when ../shared/data/clips is there, else a generated one).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from _clips import SEA as CLIP

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.benchmark import bench_lds_sizes


def analysis_time(repeats: int = 3) -> dict:
    if CLIP.exists():
        clip, name = load_clip(CLIP), CLIP.name
    else:
        rng = np.random.default_rng(0)
        clip, name = load_clip(rng.integers(0, 256, (250, 288, 352, 3), dtype=np.uint8)), "random 250x288x352"
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        learn_lds(clip, n=50)
        times.append(time.perf_counter() - t)
    return {
        "clip": name,
        "frames": clip.n_frames,
        "size": f"{clip.shape[1]}x{clip.shape[0]}",
        "median_s": float(np.median(times)),
        "max_s": float(np.max(times)),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    log = None if args.json else print
    report = bench_lds_sizes([(288, 352), (720, 1280)], frames=args.frames, log=log)
    report["analysis"] = analysis_time()
    if args.json:
        json.dump(report, sys.stdout, indent=2, default=float)
        print()
    else:
        a = report["analysis"]
        print(f"copy bandwidth {report['bandwidth']['gbs']:.1f} GB/s")
        print(f"analysis of {a['clip']} ({a['frames']} frames {a['size']}): median {a['median_s']:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
