"""Cost and outcome of ``dynatex analyze --methods auto`` against today's default (``--methods lds``).

    python benchmarks/bench_auto.py [--clips a.avi,b.gif] [--json]

For each clip of ``../shared/data/clips``: wall time of ``dynatex analyze CLIP --methods lds`` and
of ``--methods auto`` (each a fresh process, so both pay the same start-up and decode), their
ratio, and the ranking auto stored (mode, verdict, why). The issue's rule: auto becomes the
default only if it costs at most 3x the default analysis.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _clips import CLIPS

from dynatex.tiledb import open_db

NAMES = (
    "water_sea_waves_dyntex.avi",
    "steam_vapour_pot_128px.avi",
    "pendulum_clock_schoedl.mov",
    "timevarying_rusting_steel.gif",
)


def analyze(clip: Path, out: Path, methods: str) -> float | None:
    """Seconds the analysis took, or None when it failed (the default lds cannot learn a 43-frame clip)."""
    t = time.perf_counter()
    run = subprocess.run(
        [sys.executable, "-m", "dynatex.cli", "analyze", str(clip), "-o", str(out), "--methods", methods, "-q"]
    )
    return time.perf_counter() - t if run.returncode == 0 else None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", default=",".join(NAMES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.clips.split(","):
            clip = CLIPS / name
            if not clip.exists():
                print(f"skipping {name}: not in {CLIPS}", file=sys.stderr)
                continue
            lds = analyze(clip, Path(tmp) / f"{clip.stem}_lds.h5", "lds")
            auto = analyze(clip, Path(tmp) / f"{clip.stem}_auto.h5", "auto")
            with open_db(Path(tmp) / f"{clip.stem}_auto.h5") as db:
                ranking = next(iter(db)).ranking
            ratio = None if lds is None else auto / lds
            rows.append({"clip": name, "lds_s": lds, "auto_s": auto, "ratio": ratio, "ranking": ranking})
            if not args.json:
                lds_text = "failed" if lds is None else f"{lds:.1f} s"
                ratio_text = "" if ratio is None else f", ratio {ratio:.1f}"
                print(f"{name}: lds {lds_text}, auto {auto:.1f} s{ratio_text}", flush=True)
                for e in ranking:
                    print(f"  {e['rank']}. {e['mode']:<10} {e['verdict']:<5} {e['why']}", flush=True)
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
