"""Calibration of ``evaluate``'s verdicts (``analyzer/verdicts.py``) on the real clips.

    python benchmarks/calibrate_verdicts.py [--clips a.avi,b.avi] [--json]

For each clip in ``../shared/data/clips`` (and ``small_64px``): the verdicts of the clip against
itself (every one must be good) and of its second half, played twice over (a "synthesis" that is
the same texture but other frames: it should be good or poor, never bad, on a stationary clip).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip
from dynatex.analyzer.metrics import evaluate
from dynatex.analyzer.verdicts import judge

NAMES = (
    "water_sea_waves_dyntex.avi",
    "fountain_dyntex_6486110.avi",
    "flag_wind_dyntex_571c110.avi",
    "grass_straw_wind_dyntex.avi",
    "steam_vapour_pot_128px.avi",
    "small_64px/ocean_exemplar.avi",
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", default=",".join(NAMES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    for name in args.clips.split(","):
        path = CLIPS / name
        if not path.exists():
            print(f"skipping {name}: not in {CLIPS}", file=sys.stderr)
            continue
        frames = load_clip(path).frames
        half = frames[frames.shape[0] // 2 :]
        for case, out in (("itself", frames), ("second half x2", np.concatenate([half, half]))):
            v = judge(evaluate(out, frames))
            rows.append({"clip": name, "case": case, "verdicts": {x["figure"]: [x["value"], x["verdict"]] for x in v}})
            if not args.json:
                cells = ", ".join(
                    f"{k} {'-' if val is None else (f'{val:.3g}' if isinstance(val, float) else val)} {verdict}"
                    for k, (val, verdict) in rows[-1]["verdicts"].items()
                    if k != "stability"
                )
                print(f"{name:34s} {case:15s} stability {rows[-1]['verdicts']['stability'][1]}; {cells}")
    if args.json:
        json.dump(rows, sys.stdout, indent=2, default=str)
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
