"""The blend engine (mode turnpoints) per pixel format, interleaved in one process.

    python benchmarks/bench_blend.py [--size 1280x720] [--frames 43] [--rounds 15] [--json]

Random RGB frames on the device; per round, 20 calls of each case in turn, the medians in ms
and the speed against the RGB one-term frame (a device-to-host copy): ``rgb copy``; ``rgba
copy of an rgba stack`` (what the engine did before it kept the stack RGB: a plain copy of
4-byte pixels, bound 0.75x of RGB); ``rgba/bgra one term`` (kernel ``blend1``: RGB bytes read,
pixels spread as stored); and the two-term blend (a crossfade or fractional speed) in RGB and
RGBA. The device is the default one (``PYOPENCL_CTX`` picks another).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from dynatex.player.engines.blend import BlendOpenCL
from dynatex.player.opencl.context import get_context


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1280x720", help="WxH")
    ap.add_argument("--frames", type=int, default=43, help="frames in the stack")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    import pyopencl as cl

    w, h = (int(v) for v in a.size.split("x"))
    n = a.frames
    ctx = get_context(None)
    queue = cl.CommandQueue(ctx)
    frames = np.random.default_rng(0).integers(0, 256, (n, h, w, 3), dtype=np.uint8)
    engines = {f: BlendOpenCL(frames, ctx=ctx, queue=queue, format=f) for f in ("RGB", "RGBA", "BGRA")}
    rgba = np.full((n, h, w, 4), 255, np.uint8)
    rgba[..., :3] = frames
    d_rgba = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=rgba)
    del rgba
    out3, out4 = np.empty((h, w, 3), np.uint8), np.empty((h, w, 4), np.uint8)
    fb = h * w * 4
    cases = {
        "rgb copy": lambda i: engines["RGB"].render(((i, 256),), out3),
        "rgba copy of an rgba stack": lambda i: cl.enqueue_copy(
            queue, out4.reshape(-1), d_rgba, src_offset=i * fb
        ).wait(),
        "rgba one term": lambda i: engines["RGBA"].render(((i, 256),), out4),
        "bgra one term": lambda i: engines["BGRA"].render(((i, 256),), out4),
        "rgb two terms": lambda i: engines["RGB"].render(((i, 128), ((i + 1) % n, 128)), out3),
        "rgba two terms": lambda i: engines["RGBA"].render(((i, 128), ((i + 1) % n, 128)), out4),
    }
    times: dict[str, list[float]] = {k: [] for k in cases}
    for r in range(a.rounds):
        for k, call in cases.items():
            for j in range(20):
                t0 = time.perf_counter()
                call((r * 20 + j) % n)
                times[k].append(time.perf_counter() - t0)
    med = {k: float(np.median(v)) * 1e3 for k, v in times.items()}
    rows = {k: {"ms": m, "speed_vs_rgb_copy": med["rgb copy"] / m} for k, m in med.items()}
    device = ctx.devices[0]
    if a.json:
        print(json.dumps({"device": f"{device.platform.name} {device.platform.version} / {device.name}", **rows}))
        return
    print(f"{device.platform.version.split()[2:4]} {device.name}, {w}x{h}, {n} frames")
    for k, r in rows.items():
        print(f"{k:28s} {r['ms']:.3f} ms  {r['speed_vs_rgb_copy']:.2f}x rgb copy")
    for e in engines.values():
        e.close()


if __name__ == "__main__":
    main()
