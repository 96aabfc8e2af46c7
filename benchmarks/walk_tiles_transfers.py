"""Walk ``open_player(db, texture, mode='tiles')`` to the first frame and through epoch changes,
listing every host<->device transfer the player makes (issue 31's "Must show" walk).

    python benchmarks/walk_tiles_transfers.py [--size 720x1280] [--epochs 2] [--device SUBSTRING]

Counts the OpenCL copies the player enqueues (``pyopencl.enqueue_copy``, with their direction
and size) and the buffers created from host memory (``COPY_HOST_PTR``), at open, at the first
frame and at each epoch change (the time offsets moving to a new random field). The frames
themselves are written straight into the caller's array where the device shares host memory;
a copy of the frame out of a device buffer is listed as any other.
"""

from __future__ import annotations

import argparse
import collections
import tempfile
import traceback
from pathlib import Path

import numpy as np
import pyopencl as cl

from dynatex.analyzer import load_clip
from dynatex.analyzer.tiles import learn_tiles
from dynatex.player import open_player
from dynatex.tiledb import DatabaseWriter

LOG: list[tuple[str, int, str]] = []


def _caller() -> str:
    """The first frame of dynatex's player code above the copy (file:line function)."""
    for fr in reversed(traceback.extract_stack()[:-2]):
        if "/player/" in fr.filename:
            return f"{Path(fr.filename).name}:{fr.lineno} {fr.name}"
    return "?"


def _install() -> None:
    copy, buffer = cl.enqueue_copy, cl.Buffer

    def enqueue_copy(queue, dest, src, **kw):
        kind = (
            "host->device"
            if isinstance(dest, cl.MemoryObjectHolder) and not isinstance(src, cl.MemoryObjectHolder)
            else "device->host"
            if isinstance(src, cl.MemoryObjectHolder) and not isinstance(dest, cl.MemoryObjectHolder)
            else "device->device"
        )
        host = src if kind == "host->device" else dest
        LOG.append((kind, int(getattr(host, "nbytes", 0)), _caller()))
        return copy(queue, dest, src, **kw)

    class Buffer(buffer):
        def __init__(self, ctx, flags, size=0, hostbuf=None):
            if hostbuf is not None and flags & cl.mem_flags.COPY_HOST_PTR:
                LOG.append(("host->device (buffer)", int(hostbuf.nbytes), _caller()))
            super().__init__(ctx, flags, size, hostbuf)

    cl.enqueue_copy, cl.Buffer = enqueue_copy, Buffer


def _report(stage: str) -> None:
    counts = collections.Counter((k, c) for k, _, c in LOG)
    sizes = collections.defaultdict(int)
    for k, n, c in LOG:
        sizes[(k, c)] += n
    print(f"-- {stage}: {len(LOG)} transfers")
    for (k, c), m in sorted(counts.items()):
        print(f"   {m:3d} x {k:22s} {sizes[(k, c)]:>11,d} B  {c}")
    LOG.clear()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="720x1280", help="output HxW")
    ap.add_argument("--epochs", type=int, default=2)
    ap.add_argument("--device", default=None)
    a = ap.parse_args()
    h, w = (int(v) for v in a.size.split("x"))
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:48, 0:64]
    frames = np.stack(
        [
            np.clip(128 + 60 * np.sin(0.3 * xx + 0.2 * yy + i / 3) + rng.normal(0, 8, xx.shape), 0, 255)
            for i in range(40)
        ]
    ).astype(np.uint8)
    clip = load_clip(np.repeat(frames[..., None], 3, axis=3))
    model = learn_tiles(clip, tile=16, n_tiles=3, min_loop=20)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "walk.h5"
        with DatabaseWriter(path) as wr:
            wr.put_texture("t", clip.source_info())
            wr.put_method("t", "tiles", model)
        _install()
        p = open_player(path, "t", mode="tiles", backend="opencl", device=a.device, size=(h, w))
        with p:
            _report(f"open ({p.engine.__class__.__name__} on {p.ctx.devices[0].name}, {w}x{h})")
            out = np.empty(p.shape, np.uint8)
            p.next_frame(out=out)
            _report("first frame")
            for e in range(a.epochs):
                for _ in range(p._epoch):
                    p.next_frame(out=out)
                _report(f"epoch {e + 1} ({p._epoch} frames)")


if __name__ == "__main__":
    main()
