"""Frames per pass and the fused detail of ``lds`` and ``mixture``: frame rate and CPU time per
frame of ``next_frame`` for look-ahead k (frames projected per pass over the basis), with the
model's detail and without it (the projection alone), on numpy, on OpenCL and under ``auto``,
in alternating rounds (the best of each is kept: the machine is shared), so that every ratio
comes from one run.

    python benchmarks/bench_lookahead.py DB.h5 [--mode lds] [--lookahead 1,8] [--frames 48]
        [--rounds 2] [--device 0:0] [--precision float32]

CPU time counts every thread of the process (the OpenCL runtime's included). On a tree
without the ``lookahead`` option (landed main before it) only k = 1 is measured.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from dynatex.player import open_player, player_class


def measure(db: str, mode: str, backend: str, device: str | None, options: dict, detail: bool, frames: int):
    """(CPU ms per frame, frames per second, the backend that played) after two passes of warm-up."""
    kw = {"device": device} if backend != "numpy" and device else {}
    with open_player(db, mode=mode, backend=backend, seed=1, **kw, **options) as p:
        if not detail:
            p.detail_engine = None
        out = np.empty(p.shape, np.uint8)
        for _ in range(2 * options.get("lookahead", 1)):
            p.next_frame(out)
        c0, w0 = time.process_time(), time.perf_counter()
        for _ in range(frames):
            p.next_frame(out)
        c1, w1 = time.process_time(), time.perf_counter()
        return 1e3 * (c1 - c0) / frames, frames / (w1 - w0), p.backend


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("db")
    ap.add_argument("--mode", default="lds")
    ap.add_argument("--lookahead", default="1,8", help="comma-separated k values")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--device", default=None, help="OpenCL device (P:D or a name substring)")
    ap.add_argument("--precision", default="float32")
    ap.add_argument("--backends", default="numpy,opencl,auto")
    ap.add_argument("--no-detail", action="store_true", help="measure the projection alone only")
    args = ap.parse_args()
    has_lookahead = "lookahead" in [p.name for p in player_class(args.mode).options]
    ks = [int(k) for k in args.lookahead.split(",")] if has_lookahead else [1]
    details = (False,) if args.no_detail else (False, True)
    best: dict[str, list] = {}
    for _ in range(args.rounds):
        for backend in args.backends.split(","):
            for k in ks:
                for detail in details:
                    options = {"precision": args.precision, **({"lookahead": k} if has_lookahead else {})}
                    cpu, fps, used = measure(args.db, args.mode, backend, args.device, options, detail, args.frames)
                    key = f"{backend} k={k} {'detail' if detail else 'alone'}"
                    b = best.setdefault(key, [np.inf, 0.0, used])
                    best[key] = [min(b[0], cpu), max(b[1], fps), used]
    report: dict[str, object] = {
        key: {"fps": round(v[1], 1), "cpu_ms_per_frame": round(v[0], 2), "backend": v[2]} for key, v in best.items()
    }
    for key, v in best.items():
        backend, k, what = key.split()
        base = best.get(f"{backend} k=1 {what}")
        if k != "k=1" and base:
            report[f"{key}: fps over k=1"] = round(v[1] / base[1], 2)
        if what == "detail":
            alone = best[f"{backend} {k} alone"]
            report[f"{backend} {k}: detail cost (cpu ratio)"] = round(v[0] / alone[0], 2)
            report[f"{backend} {k}: detail cost (time ratio)"] = round(alone[1] / v[1], 2)
        numpy = best.get(f"numpy {k} {what}")
        if backend != "numpy" and numpy:
            report[f"{key}: fps over numpy"] = round(v[1] / numpy[1], 2)
        numpy1 = best.get(f"numpy k=1 {what}")
        if k != "k=1" and numpy1:
            report[f"{key}: fps over numpy one at a time"] = round(v[1] / numpy1[1], 2)
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
