"""Mode tiles: playback rate against the roofline and the numpy reference, and analysis time.

    python benchmarks/bench_tiles.py [--frames 300] [--rounds 5] [--json] [--no-analysis] [--sizes 1280x720,3840x2160]

- Player: ``next_frame(out=...)`` end to end into a host buffer, with smoothed drifting time
  offsets (sigma 64 px) and colour tone (consensus), at 1280x720 and 3840x2160, OpenCL and
  the numpy reference; the OpenCL kernel alone (into its device buffer) beside it. Then
  3840x2160 once more with the player's defaults (``dynatex play --mode tiles --size
  3840x2160``: smoothed offsets, no tone).
- Roofline: ``bytes_per_frame / copy GB/s``, in rounds: each round measures the copy bandwidth,
  then frames end to end and the kernel alone; a round's fraction is its roofline time over
  its median frame time, and the row reports the median (and range) over the rounds, so the
  two figures of a ratio come from the same minute of this shared machine. ``bytes_per_frame``
  is what a frame must move at least: the output written once (the kernel writes straight
  into the caller's array where the device shares host memory) plus the distinct tile
  pixels the frame reads (a few tiles over the loop frames the time offsets reach, ~1.7 MB
  here: small enough to stay in cache between frames, so the memory traffic is then about
  the output alone). Both parts are printed.
  Floors (issue 5): >= 800 frames/s at 1280x720; >= 0.5 of the roofline at 3840x2160.
- Analysis (with progress bars off): the 250-frame 352x288 grass clip from
  ``../shared/data/clips`` (floor: 2 minutes) and a generated 260-frame 1280x720 clip
  (floor: 10 minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip
from dynatex.analyzer.tiles import learn_tiles
from dynatex.benchmark import copy_bandwidth, summarize, time_calls
from dynatex.player.modes.tiles import TilesPlayer
from dynatex.tiledb import DatabaseWriter


def generated_clip(t: int, h: int, w: int, seed: int = 0) -> np.ndarray:
    """Travelling waves plus noise at any size (cheap to make at 1280x720)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    out = np.empty((t, h, w, 3), np.uint8)
    for i in range(t):
        g = np.sin(2 * np.pi * i / 23 + 0.05 * xx + 0.02 * yy) + np.sin(2 * np.pi * i / 37 - 0.03 * xx + 0.04 * yy)
        g = 128 + 50 * g + rng.normal(0, 5, (h, w)).astype(np.float32)
        g = np.clip(g, 0, 255).astype(np.uint8)
        out[i, ..., 0], out[i, ..., 1], out[i, ..., 2] = g, (g * 0.7 + 40).astype(np.uint8), 255 - g
    return out


def write_db(path: str, frames: np.ndarray, model) -> None:
    clip = load_clip(frames)
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "tiles", model)


def bench_player(path: str, size: tuple[int, int], n: int, *, defaults: bool = False, rounds: int = 5) -> dict:
    """OpenCL end to end and kernel alone in ``rounds`` rounds, each with the copy bandwidth
    measured just before it (the roofline fraction of a round compares numbers taken under the
    same load of this shared machine; the row reports the median over rounds), then numpy."""
    row: dict = {
        "size": f"{size[1]}x{size[0]}",
        "settings": "defaults" if defaults else "sigma 64, consensus tone",
        "rounds": [],
    }

    def player(backend: str) -> TilesPlayer:
        p = TilesPlayer(path, backend=backend, size=size, seed=1, tone=None if defaults else "consensus")
        if not defaults:
            p.sigma = 64.0
        return p

    with player("opencl") as p:
        buf = np.empty(p.shape, np.uint8)
        g = p.engine
        e2e, kernel = [], []
        for _ in range(rounds):
            gbs = copy_bandwidth(mbytes=128, repeats=3)["gbs"]
            times = time_calls(lambda: p.next_frame(out=buf), frames=max(10, n // rounds))
            ktimes = time_calls(lambda: g.render_on_device(1.5), frames=max(10, n // rounds))
            roof_ms = p.bytes_per_frame / (gbs * 1e9) * 1e3
            row["rounds"].append(
                {
                    "gbs": gbs,
                    "median_ms": float(np.median(times)) * 1e3,
                    "kernel_ms": float(np.median(ktimes)) * 1e3,
                    "roofline_ms": roof_ms,
                    "roofline_fraction": roof_ms / (float(np.median(times)) * 1e3),
                }
            )
            e2e.append(times)
            kernel.append(ktimes)
        row["opencl"] = summarize(np.concatenate(e2e))
        row["opencl_kernel"] = summarize(np.concatenate(kernel))
        row["direct_write"] = g.direct
        row["traffic"] = p.frame_traffic()
        row["bytes_per_frame"] = p.bytes_per_frame
    with player("numpy") as p:
        buf = np.empty(p.shape, np.uint8)
        row["numpy"] = summarize(time_calls(lambda: p.next_frame(out=buf), frames=max(5, n // 30)))
    fractions = [r["roofline_fraction"] for r in row["rounds"]]
    row["roofline_fraction"] = float(np.median(fractions))
    row["roofline_fraction_range"] = [float(min(fractions)), float(max(fractions))]
    row["roofline_ms"] = float(np.median([r["roofline_ms"] for r in row["rounds"]]))
    row["speedup_vs_numpy"] = row["numpy"]["median_ms"] / row["opencl"]["median_ms"]
    return row


def bench_analysis() -> list[dict]:
    out = []
    grass = CLIPS / "grass_straw_wind_dyntex.avi"
    if grass.exists():
        frames = load_clip(str(grass)).frames
        t0 = time.perf_counter()
        m = learn_tiles(frames)
        out.append(
            {
                "clip": "grass 352x288",
                "frames": int(frames.shape[0]),
                "seconds": time.perf_counter() - t0,
                "floor_s": 120,
                "tile": list(m.tile_size),
                "loop": m.loop_length,
            }
        )
    frames = generated_clip(260, 720, 1280)
    t0 = time.perf_counter()
    m = learn_tiles(frames)
    out.append(
        {
            "clip": "generated 1280x720",
            "frames": 260,
            "seconds": time.perf_counter() - t0,
            "floor_s": 600,
            "tile": list(m.tile_size),
            "loop": m.loop_length,
        }
    )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--sizes", default="1280x720,3840x2160")
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    ap.add_argument("--no-analysis", action="store_true")
    ap.add_argument("--no-defaults", action="store_true", help="skip the 3840x2160 run with the player's defaults")
    ap.add_argument(
        "--rounds", type=int, default=5, help="rounds per size, each with its own copy-bandwidth measurement"
    )
    ap.add_argument(
        "--constructions",
        default="quilted,ring",
        help="tile constructions to play, one database each, in one run (default quilted,ring)",
    )
    args = ap.parse_args(argv)
    result: dict = {"player": [], "analysis": []}
    with tempfile.TemporaryDirectory() as tmp:
        grass = CLIPS / "grass_straw_wind_dyntex.avi"
        frames = load_clip(str(grass)).frames if grass.exists() else generated_clip(250, 288, 352)
        paths = {}
        for construction in args.constructions.split(","):
            paths[construction] = os.path.join(tmp, f"tiles_{construction}.h5")
            write_db(paths[construction], frames, learn_tiles(frames, construction=construction))
        runs = [(tuple(int(v) for v in text.lower().split("x"))[::-1], False) for text in args.sizes.split(",")]
        if not args.no_defaults:
            runs.append(((2160, 3840), True))
        for (size, defaults), construction in [(r, c) for r in runs for c in paths]:
            row = bench_player(paths[construction], size, args.frames, defaults=defaults, rounds=args.rounds)
            row["construction"] = construction
            result["player"].append(row)
            tr = row["traffic"]
            lo, hi = row["roofline_fraction_range"]
            gbs = [r["gbs"] for r in row["rounds"]]
            print(
                f"{row['construction']} {row['size']} ({row['settings']}): "
                f"OpenCL {row['opencl']['fps']:.0f} frames/s (median {row['opencl']['median_ms']:.2f} ms, "
                f"p99 {row['opencl']['p99_ms']:.2f} ms; kernel alone {row['opencl_kernel']['median_ms']:.2f} ms), "
                f"numpy {row['numpy']['fps']:.1f} frames/s, "
                f"x{row['speedup_vs_numpy']:.1f} vs numpy, {row['roofline_fraction']:.2f} of the roofline "
                f"(median of {len(row['rounds'])} rounds, {lo:.2f}-{hi:.2f}; roofline {row['roofline_ms']:.2f} ms at "
                f"{min(gbs):.1f}-{max(gbs):.1f} GB/s for {row['bytes_per_frame'] / 1e6:.1f} MB: "
                f"{tr['output'] / 1e6:.1f} MB output + {tr['stored'] / 1e6:.1f} MB distinct tile data)",
                file=sys.stderr,
            )
    if not args.no_analysis:
        result["analysis"] = bench_analysis()
        for a in result["analysis"]:
            print(
                f"analysis {a['clip']} ({a['frames']} frames): {a['seconds']:.1f} s (floor {a['floor_s']} s)",
                file=sys.stderr,
            )
    if args.json:
        print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
