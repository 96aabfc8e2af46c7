"""Cost per frame of the detail pass of ``lds`` and ``mixture``: CPU seconds per frame (every
thread of the process, PoCL's included, so the figure holds on a shared, loaded machine) and
wall-clock frame rate, with the detail and without it (the projection alone, as before the
part existed), on both backends, alternating the two several times.

    python benchmarks/bench_detail.py DB.h5 [--mode lds] [--frames 200] [--rounds 3] [--device 1:0]

The load average (1 minute) before and after is printed with the figures: on a shared machine
only the ratios of one run are worth comparing.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from dynatex.player import open_player


def measure(db: str, mode: str, backend: str, detail: bool, frames: int, device: str | None) -> tuple[float, float]:
    """(CPU ms per frame, frames per second) of ``frames`` frames after 20 of warm-up."""
    kw = {"device": device} if backend == "opencl" and device else {}
    with open_player(db, mode=mode, backend=backend, seed=1, **kw) as p:
        if not detail:
            p.detail_engine = None
        out = np.empty(p.shape, np.uint8)
        for _ in range(20):
            p.next_frame(out)
        c0, w0 = time.process_time(), time.perf_counter()
        for _ in range(frames):
            p.next_frame(out)
        c1, w1 = time.process_time(), time.perf_counter()
    return 1e3 * (c1 - c0) / frames, frames / (w1 - w0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("db")
    ap.add_argument("--mode", default="lds")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--device", help="OpenCL device (as play's --device; default: the player's choice)")
    args = ap.parse_args()
    load = [os.getloadavg()[0]]
    best: dict[str, list[float]] = {}
    for _ in range(args.rounds):
        for backend in ("opencl", "numpy"):
            for detail in (False, True):
                cpu, fps = measure(args.db, args.mode, backend, detail, args.frames, args.device)
                key = f"{backend} {'detail' if detail else 'projection alone'}"
                b = best.setdefault(key, [np.inf, 0.0])
                best[key] = [min(b[0], cpu), max(b[1], fps)]
    report = {k: {"cpu_ms_per_frame": round(v[0], 3), "fps": round(v[1], 1)} for k, v in best.items()}
    for backend in ("opencl", "numpy"):
        a, d = best[f"{backend} projection alone"], best[f"{backend} detail"]
        report[f"{backend} cost ratio (cpu)"] = round(d[0] / a[0], 3)
    load.append(os.getloadavg()[0])
    report["load average before, after"] = load
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
