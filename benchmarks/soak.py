"""Soak: play a million frames of ``lds`` and ``tiles`` and watch resident memory.

    python benchmarks/soak.py [--frames 1000000] [--modes lds,tiles] [--backends auto,numpy] [--json]

A game plays for hours; a player that leaks a few bytes per frame (a buffer, an event, a
cached array per call) ends as an out-of-memory kill. For each mode and backend this opens
one player on a small generated texture (frames 32x24 for ``lds``, a 64x64 canvas for
``tiles``: small frames, so that the frame count, not the pixel work, dominates), pulls
``--frames`` frames into one caller buffer and samples the resident set size (RSS, from
``/proc/self/statm``) every ``--sample`` frames. Growth is the last sample minus the
sample at the end of the warm-up (the first ``--warmup`` frames: allocators and driver
caches settle there). Target: less than 1 MB of growth after the warm-up.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.tiles import learn_tiles
from dynatex.player import open_player
from dynatex.tiledb import DatabaseWriter

TARGET_MB = 1.0
_PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_bytes() -> int:
    """Resident set size of this process now (``/proc/self/statm``, Linux)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * _PAGE


def wave_clip(t: int, h: int, w: int, seed: int = 0) -> np.ndarray:
    """Travelling waves plus a little noise, ``(t, h, w, 3)`` uint8."""
    rng = np.random.default_rng(seed)
    tt, yy, xx = np.meshgrid(np.arange(t), np.arange(h), np.arange(w), indexing="ij")
    g = np.sin(2 * np.pi * tt / 17 + 0.3 * xx + 0.2 * yy) + np.sin(2 * np.pi * tt / 11 - 0.2 * xx + 0.4 * yy)
    g = np.clip(128 + 50 * g + rng.normal(0, 3, g.shape), 0, 255).astype(np.uint8)
    return np.stack([g, (g * 0.8 + 20).astype(np.uint8), 255 - g], axis=3)


def make_database(path: str) -> None:
    clip = load_clip(wave_clip(80, 24, 32))
    tiles_clip = load_clip(wave_clip(80, 48, 48, seed=1))
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture("lds", clip.source_info())
        w.put_method("lds", "lds", learn_lds(clip, n=12))
        w.put_texture("tiles", tiles_clip.source_info())
        w.put_method("tiles", "tiles", learn_tiles(tiles_clip, tile=16))


def soak(path: str, mode: str, backend: str, frames: int, sample: int, warmup: int) -> dict:
    options = {"size": (64, 64)} if mode == "tiles" else {}
    with open_player(path, mode, mode=mode, backend=backend, seed=1, **options) as p:
        out = np.empty(p.shape, np.uint8)
        samples: list[tuple[int, int]] = [(0, rss_bytes())]
        t0 = time.perf_counter()
        for i in range(1, frames + 1):
            p.next_frame(out=out)
            if i % sample == 0 or i == frames:
                samples.append((i, rss_bytes()))
        seconds = time.perf_counter() - t0
        used = p.backend
    after = [s for s in samples if s[0] >= warmup] or samples[-1:]
    base = after[0][1]
    growth = samples[-1][1] - base
    peak = max(r for _, r in after) - base
    return {
        "mode": mode,
        "backend": backend,
        "played_on": used,
        "frames": frames,
        "shape": list(out.shape),
        "seconds": seconds,
        "fps": frames / seconds,
        "rss_start_mb": samples[0][1] / 2**20,
        "rss_after_warmup_mb": base / 2**20,
        "rss_end_mb": samples[-1][1] / 2**20,
        "growth_mb": growth / 2**20,
        "peak_growth_mb": peak / 2**20,
        "ok": growth < TARGET_MB * 2**20,
        "samples": samples,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--modes", default="lds,tiles")
    ap.add_argument("--backends", default="auto,numpy")
    ap.add_argument("--sample", type=int, default=10_000, help="frames between RSS samples")
    ap.add_argument(
        "--warmup",
        type=int,
        default=None,
        help="frames before the baseline sample (default: 5%% of --frames, at least one sample)",
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    warmup = args.warmup if args.warmup is not None else max(args.sample, args.frames // 20)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "soak.h5")
        make_database(path)
        for mode in args.modes.split(","):
            for backend in args.backends.split(","):
                row = soak(path, mode, backend, args.frames, args.sample, warmup)
                rows.append(row)
                if not args.json:
                    print(
                        f"{mode:6s} {backend:5s} ({row['played_on']:6s}) {row['frames']} frames "
                        f"{tuple(row['shape'][:2])} in {row['seconds']:.0f} s = {row['fps']:.0f} fps; RSS "
                        f"{row['rss_start_mb']:.1f} -> {row['rss_after_warmup_mb']:.1f} MB after warm-up -> "
                        f"{row['rss_end_mb']:.1f} MB: growth {row['growth_mb']:+.3f} MB "
                        f"(peak {row['peak_growth_mb']:+.3f}) {'ok' if row['ok'] else 'OVER 1 MB'}",
                        flush=True,
                    )
    if args.json:
        print(json.dumps(rows, indent=1))
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
