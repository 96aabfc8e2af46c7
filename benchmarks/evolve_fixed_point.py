"""Mode evolve's fixed-point blend against the float32 one it replaced: the largest difference
per frame and a contact sheet (source frame, float32, fixed point, difference x32).

    python benchmarks/evolve_fixed_point.py CLIP OUT_PREFIX [--sizes 128x128,1080x1920] [--jitter 4]

For each canvas size (height x width), CLIP is quilted (``learn_quilt``, seed 1) and frames at
clock times spread over the clip (fractional, so frames are interpolated) are drawn by the numpy
reference and by the float32 formulas of the reference before the fixed point (kept here):
``v0 + f (v1 - v0)`` per source, ``first + a (second - first)`` per band, times the gain,
rounded to nearest even. Writes OUT_PREFIX_HxW.png (rows: times; columns: the source frame at
that clock, float32, fixed point, |difference| x 32) and, for canvases wider than 640 pixels, a
1:1 crop of its centre as OUT_PREFIX_HxW_crop.png; prints the largest difference and the share
of bytes that differ per frame.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import cv2
import numpy as np

from dynatex.analyzer import load_clip
from dynatex.analyzer.quilt import learn_quilt
from dynatex.player.modes.evolve import EvolvePlayer
from dynatex.tiledb import DatabaseWriter

TIMES = (0.0, 12.3, 33.7, 50.5, 75.25, 98.6)
CROP = 400


def float_sample(flat, pix, s, *, loop, interpolate):
    n = flat.shape[0]
    si = np.floor(s).astype(np.int64)
    fold = (lambda i: np.mod(i, n)) if loop else (lambda i: np.clip(i, 0, n - 1))
    v = flat[fold(si), pix].astype(np.float32)
    if interpolate:
        f = (s - si.astype(np.float32))[..., None].astype(np.float32)
        v = v + f * (flat[fold(si + 1), pix].astype(np.float32) - v)
    return v


def float_frame(e, t: float, source_time, loop: bool) -> np.ndarray:
    """The float32 reference's RGB frame (before the fixed point)."""
    t32 = np.float32(t)
    v = float_sample(e.flat, e.pix, source_time(e.rate, e.labels, t32), loop=loop, interpolate=e.interpolate)
    if e.blend is not None:
        wq, pix2, labels2 = e.blend
        sel = wq > 0
        s2 = source_time(None if e.rate is None else e.rate[sel], labels2[sel], t32)
        v2 = float_sample(e.flat, pix2[sel], s2, loop=loop, interpolate=e.interpolate)
        a = (wq[sel].astype(np.float32) * np.float32(1.0 / 256.0))[:, None]
        v[sel] = v[sel] + a * (v2 - v[sel])
    if e.gain is not None:
        v = v * e.gain
    return np.clip(np.rint(v), 0, 255).astype(np.uint8).reshape(*e.shape, 3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clip")
    ap.add_argument("out")
    ap.add_argument("--sizes", default="128x128,1080x1920")
    ap.add_argument("--jitter", type=float, default=4.0)
    a = ap.parse_args()
    clip = load_clip(a.clip)
    frames = clip.frames
    with tempfile.TemporaryDirectory() as tmp:
        for size in a.sizes.split(","):
            h, w = (int(v) for v in size.split("x"))
            path = os.path.join(tmp, f"q{h}x{w}.h5")
            with DatabaseWriter(path, overwrite=True) as wr:
                wr.put_texture("t", clip.source_info())
                wr.put_frames("t", frames)
                wr.put_method("t", "quilt", learn_quilt(frames, size=(h, w), seed=1))
            with EvolvePlayer(path, backend="numpy", seed=1, jitter=a.jitter) as p:
                e, st, loop = p.engine, p._source_time, p._end == "loop"
                rows, worst = [], 0
                for t in TIMES:
                    fixed = np.empty((h, w, 3), np.uint8)
                    e.draw(fixed, t, source_time=st, loop=loop)
                    flt = float_frame(e, t, st, loop)
                    d = np.abs(fixed.astype(np.int16) - flt).astype(np.uint8)
                    worst = max(worst, int(d.max()))
                    print(f"{h}x{w} t={t:6.2f}: max |fixed - float32| {d.max()}, {np.mean(d > 0):.2%} of bytes differ")
                    src = frames[min(int(round(t)), len(frames) - 1)]
                    src = cv2.resize(src, (src.shape[1] * h // src.shape[0], h), interpolation=cv2.INTER_NEAREST)
                    rows.append((src, flt, fixed, np.minimum(d.astype(np.int32) * 32, 255).astype(np.uint8)))
                print(f"{h}x{w}: largest difference {worst}")
            sheet = np.concatenate([np.concatenate(r, axis=1) for r in rows], axis=0)
            scale = 1 if w <= 640 else 3
            small = (
                sheet
                if scale == 1
                else cv2.resize(sheet, None, fx=1 / scale, fy=1 / scale, interpolation=cv2.INTER_AREA)
            )
            cv2.imwrite(f"{a.out}_{h}x{w}.png", cv2.cvtColor(small, cv2.COLOR_RGB2BGR))
            if w > 640:
                y0, x0 = (h - CROP) // 2, (w - CROP) // 2
                crop = [
                    np.concatenate([r[k][y0 : y0 + CROP, x0 : x0 + CROP] for k in (1, 2, 3)], axis=1) for r in rows[1:4]
                ]
                cv2.imwrite(f"{a.out}_{h}x{w}_crop.png", cv2.cvtColor(np.concatenate(crop, axis=0), cv2.COLOR_RGB2BGR))
    sys.exit(0)


if __name__ == "__main__":
    main()
