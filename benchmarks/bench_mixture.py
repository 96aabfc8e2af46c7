"""Subspace-mixture benchmark: analysis time of a 250-frame 352x288 clip, and the mixture
player's frame rate against the numpy reference and the memory-bandwidth roofline of its
stacked basis (measured in the same run).

    python benchmarks/bench_mixture.py [--frames 200] [--repeats 3] [--json]

Uses the real sea-waves clip when ../shared/data/clips is there, else a generated clip of
the same size. Floors (issue 7): analysis within 60 s; player >= 0.7 of the roofline.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _clips import SEA as CLIP

from dynatex.analyzer import load_clip
from dynatex.analyzer.mixture import learn_mixture
from dynatex.benchmark import bench_player, copy_bandwidth, format_result
from dynatex.tiledb import DatabaseWriter

ANALYSIS_FLOOR_S = 60.0
ROOFLINE_FLOOR = 0.7


def _clip():
    if CLIP.exists():
        return load_clip(CLIP), CLIP.name
    t = np.arange(250)[:, None, None, None]
    y = np.arange(288)[None, :, None, None]
    x = np.arange(352)[None, None, :, None]
    frames = 128 + 50 * np.sin(0.2 * t + 0.05 * x + 0.03 * y) * np.cos(0.13 * t - 0.04 * y)
    frames = frames + np.random.default_rng(0).normal(0, 4, (250, 288, 352, 1))
    return load_clip(np.repeat(frames.clip(0, 255).astype(np.uint8), 3, axis=3)), "generated 250x288x352"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    clip, name = _clip()
    times = []
    model = None
    for _ in range(args.repeats):
        t = time.perf_counter()
        model = learn_mixture(clip)
        times.append(time.perf_counter() - t)
    report: dict = {
        "analysis": {
            "clip": name,
            "frames": clip.n_frames,
            "size": f"{clip.shape[1]}x{clip.shape[0]}",
            "median_s": float(np.median(times)),
            "max_s": float(np.max(times)),
            "floor_s": ANALYSIS_FLOOR_S,
            "components": model.components,
            "dim": model.dim,
            "order": model.order,
        }
    }
    bw = copy_bandwidth()
    report["bandwidth"] = bw
    report["results"] = []
    with tempfile.TemporaryDirectory(prefix="dynatex-bench-") as tmp:
        path = Path(tmp) / "mix.h5"
        with DatabaseWriter(path) as w:
            w.put_texture("t", clip.source_info())
            w.put_method("t", "mixture", model)
        for prec in ("float32", "float16"):
            r = bench_player(
                path, mode="mixture", frames=args.frames, bandwidth_gbs=bw["gbs"], options={"precision": prec}
            )
            r.update(precision=prec, rows=model.stacked_basis.shape[0], floor=ROOFLINE_FLOOR)
            report["results"].append(r)
            if not args.json:
                print(format_result(r))
    if args.json:
        json.dump(report, sys.stdout, indent=2, default=float)
        print()
    else:
        a = report["analysis"]
        print(f"copy bandwidth {bw['gbs']:.1f} GB/s")
        print(
            f"analysis of {a['clip']} ({a['frames']} frames {a['size']}, S={a['components']} d={a['dim']}, "
            f"AR({a['order']})): median {a['median_s']:.2f} s, max {a['max_s']:.2f} s (floor {ANALYSIS_FLOOR_S:.0f} s)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
