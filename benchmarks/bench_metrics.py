"""Time ``dynatex.analyzer.metrics.evaluate`` on 300 frames of 352x288 against their source.

Usage: ``python benchmarks/bench_metrics.py [--clip PATH] [--repeat N] [--json]``

The source is a 352x288 DynTex clip (default ``../shared/data/clips/water_sea_waves_dyntex.avi``
beside the checkout, else a generated drifting-noise clip); the output is 300 frames made
by playing the source forward and back (ping-pong), with a 64x64 tile grid as boundaries
and the turn points as events. Prints the time of each metric and of the whole report.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from _clips import SEA as DEFAULT_CLIP

from dynatex.analyzer import metrics as m


def generated(t: int = 250, h: int = 288, w: int = 352, seed: int = 0) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    base = cv2.GaussianBlur(rng.normal(0, 1, (h + 2 * t, w + 2 * t)).astype(np.float32), (0, 0), 4)
    base = (base - base.mean()) / base.std()
    frames = np.stack([base[2 * i // 3 : 2 * i // 3 + h, i : i + w] for i in range(t)])
    return np.repeat((128 + 40 * frames).clip(0, 255).astype(np.uint8)[..., None], 3, axis=-1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clip", default=str(DEFAULT_CLIP))
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if Path(args.clip).exists():
        from dynatex.analyzer import load_clip

        source = load_clip(args.clip, size=(288, 352)).frames
        name = Path(args.clip).name
    else:
        source, name = generated(), "generated drifting noise"
    t = source.shape[0]
    order = np.concatenate([np.arange(t), np.arange(t - 2, 0, -1)])
    order = np.resize(order, args.frames)
    output = source[order]
    labels = m.grid_labels(output.shape[1:3], 64)
    events = [int(i) for i in range(1, len(order) - 1) if (order[i + 1] - order[i]) != (order[i] - order[i - 1])]
    timings: dict[str, float] = {}

    def timed(key, fn, *a, **k):
        t0 = time.perf_counter()
        r = fn(*a, **k)
        timings[key] = round(time.perf_counter() - t0, 3)
        return r

    timed("stability", m.stability, output, source)
    timed("seam_visibility", m.seam_visibility, output, labels)
    timed("temporal_discontinuity", m.temporal_discontinuity, output, events, source=source)
    timed("frame_step_ratio", m.frame_step_ratio, output, source)
    timed("spectrum_distance", m.spectrum_distance, output, source)
    timed("patch_distances", m.patch_distances, output, source)
    timed("frame_coverage", m.frame_coverage, output, source)
    timed("repetition_lag", m.repetition_lag, output, source=source)
    best = float("inf")
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        report = m.evaluate(output, source, labels=labels, events=events)
        best = min(best, time.perf_counter() - t0)
    result = {
        "source": name,
        "source_frames": t,
        "output_frames": int(output.shape[0]),
        "size": f"{output.shape[2]}x{output.shape[1]}",
        "evaluate_s": round(best, 3),
        "per_metric_s": timings,
        "report": {k: v for k, v in report.items() if k != "stability"},
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(f"{result['output_frames']} frames {result['size']} against {name} ({t} frames): evaluate() {best:.2f} s")
        for k, v in timings.items():
            print(f"  {k:24s} {v:7.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
