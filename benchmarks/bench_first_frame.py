"""Time to first frame in a new process, per mode: the first run on a machine (no self-test
verdict cached, PoCL's kernel cache empty) and later runs (both caches warm).

    python benchmarks/bench_first_frame.py [--runs 3] [--json]

Each run is a fresh ``python`` process that imports the player, opens the mode on
``player/selftest.h5`` (tiles at 1280x720) and renders one frame; the time is measured
inside it from before the import to the first frame. "first" runs get an empty cache folder
(``XDG_CACHE_HOME``, with ``DYNATEX_CACHE_DIR`` and ``POCL_CACHE_DIR`` inside it: no
self-test verdict, no compiled kernel of PoCL or pyopencl), so the device self-test and
every kernel build happen; "later" runs reuse the folder of a first run. The device is the
player's default (``PYOPENCL_CTX`` picks another). Target (issue 15): later runs within 1 s.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

MODES = {"lds": {}, "mixture": {}, "turnpoints": {}, "tiles": {"size": (720, 1280)}, "evolve": {}}

CHILD = """
import time; t0 = time.perf_counter()
import sys, json
from dynatex.player import open_player
from dynatex.player.opencl import selftest
mode, options = sys.argv[1], json.loads(sys.argv[2])
with open_player(selftest._db_path(), selftest.TEXTURE, mode=mode, backend="opencl", **options) as p:
    t1 = time.perf_counter()
    p.next_frame()
    t2 = time.perf_counter()
    print(json.dumps({"open_s": t1 - t0, "first_frame_s": t2 - t0,
                      "device": " ".join(p.ctx.devices[0].platform.version.split()[:4])}))
"""


def run_once(mode: str, options: dict, env: dict) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", CHILD, mode, json.dumps(options)], capture_output=True, text=True, env=env, timeout=600
    )
    if done.returncode != 0:
        last = done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"exit status {done.returncode}"
        raise RuntimeError(f"{mode}: {last}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs of each kind per mode (default 3)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    results = {}
    for mode, options in MODES.items():
        first, later, device = [], [], ""
        for _ in range(args.runs):
            with tempfile.TemporaryDirectory() as cache:
                env = dict(
                    os.environ,
                    XDG_CACHE_HOME=cache,
                    DYNATEX_CACHE_DIR=os.path.join(cache, "dynatex"),
                    POCL_CACHE_DIR=os.path.join(cache, "pocl"),
                )
                r = run_once(mode, options, env)
                first.append(r["first_frame_s"])
                device = r["device"]
                later.append(run_once(mode, options, env)["first_frame_s"])
        results[mode] = {
            "first_run_s": float(np.median(first)),
            "first_run_range": [min(first), max(first)],
            "later_run_s": float(np.median(later)),
            "later_run_range": [min(later), max(later)],
            "device": device,
        }
        if not args.json:
            r = results[mode]
            print(
                f"{mode:11s} first run {r['first_run_s']:6.2f} s ({min(first):.2f}-{max(first):.2f})   "
                f"later runs {r['later_run_s']:5.2f} s ({min(later):.2f}-{max(later):.2f})   [{device}]"
            )
    if args.json:
        print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
