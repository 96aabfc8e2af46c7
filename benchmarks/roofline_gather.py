"""Gather modes against the memory roofline, per OpenCL CPU implementation, in one run.

    python benchmarks/roofline_gather.py [--devices skylake,Intel] [--formats RGB,BGRA] [--rounds 5]
        [--frames 40] [--json]

For each device named (a substring of its name, as ``device=``): mode tiles (quilted, the
default construction for one texture, on the real grass clip; smoothed offsets, 1280x720)
and mode evolve (1024x1024 quilt of the rusting-steel time-lapse, jitter 4), the kernel alone
into its device buffer. Rounds alternate: the copy bandwidth (:func:`dynatex.benchmark.copy_bandwidth`,
the faster of numpy's copy and an OpenCL streaming copy) then each kernel, so that a round's
fraction (``bytes_per_frame / bandwidth`` over the kernel's median time) compares figures
taken under the same load of a shared machine; the row reports the median and range over
rounds. ``bytes_per_frame`` is the least a frame must move (the player's own figure).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_tiles import CLIPS, generated_clip  # noqa: E402
from bench_tiles import write_db as write_tiles_db  # noqa: E402

from dynatex.analyzer import load_clip  # noqa: E402
from dynatex.analyzer.quilt import learn_quilt, spreading_clip  # noqa: E402
from dynatex.analyzer.tiles import learn_tiles  # noqa: E402
from dynatex.benchmark import copy_bandwidth, time_calls  # noqa: E402
from dynatex.player.modes.evolve import EvolvePlayer  # noqa: E402
from dynatex.player.modes.tiles import TilesPlayer  # noqa: E402
from dynatex.tiledb import DatabaseWriter  # noqa: E402


def databases(folder: str) -> tuple[str, str]:
    tiles, evolve = os.path.join(folder, "tiles.h5"), os.path.join(folder, "evolve.h5")
    grass = CLIPS / "grass_straw_wind_dyntex.avi"
    clip = load_clip(str(grass)).frames if grass.exists() else generated_clip(250, 288, 352)
    write_tiles_db(tiles, clip, learn_tiles(clip))
    steel = CLIPS / "timevarying_rusting_steel.gif"
    frames = load_clip(steel).frames if steel.exists() else spreading_clip(100, 128, 128)
    c = load_clip(frames)
    with DatabaseWriter(evolve, overwrite=True) as w:
        w.put_texture("t", c.source_info())
        w.put_frames("t", c.frames)
        w.put_method("t", "quilt", learn_quilt(frames, size=(1024, 1024)))
    return tiles, evolve


def players(tiles: str, evolve: str, device: str, format: str = "RGB") -> dict:
    t = TilesPlayer(tiles, backend="opencl", device=device, size=(720, 1280), seed=1, format=format)
    t.sigma = 64.0
    e = EvolvePlayer(evolve, backend="opencl", device=device, seed=1, jitter=4.0, format=format)
    e.speed = 0.37
    buf = np.empty(t.shape, np.uint8)
    t.next_frame(out=buf)
    return {
        "tiles quilted 1280x720": (t, lambda: t.engine.render_on_device(1.5), t.bytes_per_frame),
        "evolve 1024x1024 jitter": (
            e,
            lambda: e.engine.run_on_device(e.time, source_time=e._source_time, loop=e.end == "loop").wait(),
            e.bytes_per_frame,
        ),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default="skylake,Intel", help="comma-separated device name substrings")
    ap.add_argument("--formats", default="RGB", help="comma-separated pixel formats of the players (RGB, RGBA, BGRA)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=40, help="timed kernels per round")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        tiles, evolve = databases(tmp)
        opened = {(d, f): players(tiles, evolve, d, f) for d in a.devices.split(",") for f in a.formats.split(",")}
        for _ in range(a.rounds):
            gbs = copy_bandwidth(mbytes=128, repeats=3)["gbs"]
            for (d, f), ps in opened.items():
                for what, (p, kernel, nbytes) in ps.items():
                    ms = float(np.median(time_calls(kernel, frames=a.frames, warmup=3))) * 1e3
                    row = rows.setdefault(f"{what} {f} on {p.ctx.devices[0].platform.name.split()[0]} {d}", [])
                    row.append((ms, nbytes / (gbs * 1e9) * 1e3 / ms, gbs))
        for ps in opened.values():
            for p, _, _ in ps.values():
                p.close()
    out = {
        k: {
            "kernel_ms": float(np.median([r[0] for r in v])),
            "fraction": float(np.median([r[1] for r in v])),
            "fraction_range": [float(min(r[1] for r in v)), float(max(r[1] for r in v))],
            "gbs": float(np.median([r[2] for r in v])),
        }
        for k, v in rows.items()
    }
    if a.json:
        print(json.dumps(out))
        return
    for k, r in out.items():
        lo, hi = r["fraction_range"]
        print(
            f"{k:58s} kernel {r['kernel_ms']:6.2f} ms  {r['fraction']:.2f} of roofline "
            f"({lo:.2f}-{hi:.2f}) at {r['gbs']:.1f} GB/s"
        )


if __name__ == "__main__":
    main()
