"""Calibration of ``local_novelty`` (``evaluate``'s mixed-positions figure) on the real clips.

    python benchmarks/calibrate_novelty.py OUTDIR [--cases flag,sea] [--json]

Per case: the default analysis with the case's methods into ``OUTDIR``, each mode played 350
frames (seed 1) and the last 300 kept, then ``local_novelty`` of each output, of the source
against itself, of its second half played twice, and of crossfades of source frames a third of
the clip apart; beside it ``double_image``'s median over ``double_image_level`` (the nearest
whole source frame), which cannot tell mixing from an unseen stretch of the clip.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip
from dynatex.analyzer.auto import play_mode
from dynatex.analyzer.metrics import double_image, double_image_level, local_novelty

CASES = {
    "flag": ("flag_wind_dyntex_571c110.avi", "lds,mixture,turnpoints"),
    "sea": ("water_sea_waves_dyntex.avi", "lds,tiles"),
    "grass": ("grass_straw_wind_dyntex.avi", "lds,tiles"),
    "fire64": ("small_64px/fire_dyntex_64px.avi", "mixture,turnpoints"),
    "ocean64": ("small_64px/ocean_dyntex_64px.avi", "mixture"),
    "waterfall64": ("small_64px/waterfall1_dyntex_64px.avi", "mixture"),
    "fountain": ("fountain_dyntex_6486110.avi", "lds"),
    "steam": ("steam_vapour_pot_128px.avi", "mixture", "--mix-dim", "5"),  # 64 frames: d=10 fails
    "smoke64": ("small_64px/fire_smoke_dyntex_64px.avi", "mixture", "--mix-dim", "5"),
    "snow64": ("small_64px/snow_dyntex_64px.avi", "mixture"),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("outdir")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out_dir = Path(args.outdir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for case in args.cases.split(","):
        name, methods, *extra = CASES[case]
        clip = CLIPS / name
        if not clip.exists():
            print(f"skipping {name}: not in {CLIPS}", file=sys.stderr)
            continue
        db = out_dir / f"{case}.h5"
        if not db.exists():
            cmd = [sys.executable, "-m", "dynatex.cli", "analyze", str(clip), "-o", str(db), "--methods", methods]
            subprocess.run([*cmd, "-q", *extra], check=True)
        src = load_clip(clip).frames
        t, half = len(src), len(src) // 2
        first = np.arange(t - t // 3)
        outputs = {
            "itself": src,
            "second half x2": np.concatenate([src[half:], src[half:]]),
            "crossfade t, t+T/3": ((src[first].astype(np.float32) + src[first + t // 3]) / 2).round().astype(np.uint8),
        }
        for method in methods.split(","):
            outputs[method] = play_mode(db, clip.stem, method, 350, seed=1)[50:]
        level = double_image_level(src)
        for label, frames in outputs.items():
            row = {
                "case": case,
                "output": label,
                "local_novelty": local_novelty(frames, src),
                "double_image_over_level": float(np.median(double_image(frames, src))) / level,
            }
            rows.append(row)
            if not args.json:
                print(
                    f"{case:12s} {label:20s} local novelty {row['local_novelty']:.2f}  "
                    f"double image / level {row['double_image_over_level']:.2f}",
                    flush=True,
                )
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
