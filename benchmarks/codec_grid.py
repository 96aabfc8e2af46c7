"""The codec's block grid on real clips and in what lds and mixture draw from them.

Per clip: whether :func:`~dynatex.analyzer.deblock.detect_grid` finds a grid (and its ratios), the
blockiness of the source and of the values the models learn from (tone values where the clip
gets a tone map; mean absolute step between neighbours at the 8-pixel block boundaries over the
mean everywhere, x and y, on the mean of the channels, the median over frames: ~1.0 on a clip
without a grid), and the seconds the detection and
the smoothing take. With ``--outputs DIR ...``: the same blockiness of the output frames that
``benchmarks/quality_projection.py`` saved there (``NAME_out.npy``), for a before/after table.

    python benchmarks/codec_grid.py [--clips sea,grass,flames] [--outputs before after]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from _clips import CLIPS

NAMES = {
    "sea": "water_sea_waves_dyntex.avi",
    "grass": "grass_straw_wind_dyntex.avi",
    "fountain": "fountain_dyntex_6486110.avi",
    "flag": "flag_wind_dyntex_571c110.avi",
    "flames": "fire_flames_720p.mp4",
    "flames_mix": "fire_flames_720p.mp4",
    "steam": "steam_vapour_pot_128px.avi",
    "clock": "pendulum_clock_schoedl.mov",
    "honey": "timevarying_melting_honey.gif",
    "fire64": "small_64px/fire_dyntex_64px.avi",
    "ocean64": "small_64px/ocean_dyntex_64px.avi",
    "smoke64": "small_64px/fire_smoke_dyntex_64px.avi",
}


def blockiness(frames: np.ndarray, period: int = 8) -> tuple[float, float]:
    """Median over ``frames`` (``(T, H, W, C)``) of the mean step at the block boundaries over the
    mean step, along x and along y."""
    out = []
    for f in frames:
        g = f.astype(np.float32).mean(axis=-1)
        dx, dy = np.abs(np.diff(g, axis=1)), np.abs(np.diff(g, axis=0))
        out.append((dx[:, period - 1 :: period].mean() / dx.mean(), dy[period - 1 :: period].mean() / dy.mean()))
    bx, by = np.median(np.array(out), axis=0)
    return round(float(bx), 3), round(float(by), 3)


def main() -> None:
    from dynatex.analyzer import deblock
    from dynatex.analyzer.tone import choose as choose_tone
    from dynatex.analyzer.video import load_clip_path

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", default="sea,grass,fountain,flag,steam,honey,fire64,ocean64,smoke64")
    ap.add_argument("--outputs", nargs="*", default=[], help="folders of quality_projection.py outputs")
    args = ap.parse_args()
    for name in args.clips.split(","):
        frames = load_clip_path(str(CLIPS / NAMES[name])).frames
        tone = choose_tone(frames, "auto")
        t0 = time.perf_counter()
        grid = deblock.detect_grid(frames)
        t1 = time.perf_counter()
        values, _ = deblock.learning_values(frames, grid if grid.any else None, tone)
        t2 = time.perf_counter()
        learned = values.reshape(frames.shape)
        row = {
            "clip": name,
            "grid": grid.describe(),
            "source": blockiness(frames[:: max(1, len(frames) // 16)]),
            "learned": blockiness(learned[:: max(1, len(frames) // 16)]),
            "detect_s": round(t1 - t0, 2),
            "smooth_s": round(t2 - t1, 2),
        }
        for folder in args.outputs:
            path = os.path.join(folder, f"{name}_out.npy")
            if os.path.exists(path):
                row[f"out:{folder}"] = blockiness(np.load(path)[::10])
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
