"""Contact sheets of the colour set (the ``gamut`` part), from two OUTDIRs of
``quality_projection.py`` (databases analysed before and after it: the same model but the part).

Per clip, the three frames (of 64 after 1,000) where the output before had the most pixels of
colours the clip never had: ``{clip}_gamut.png``, rows of the source frame, the output before,
the output after and the before with those pixels marked magenta, at 1:1; ``{clip}_crop.png``,
the same for a region (``--crop``, default the flag's top edge), at 1:1 and at 4x; and
``{clip}_1080_{before,after}.png``, the worst frame scaled to 1080 rows on a 1920x1080 canvas,
as a full-screen play shows it. Prints the share of such pixels before and after. ``--local``:
colours that the pixel's 16 x 16 region of the source never had
(:func:`~dynatex.analyzer.metrics.gamut.local_colour_sets` of the whole clip) instead.

    python benchmarks/gamut_sheets.py BEFORE AFTER OUTDIR [--clips flag,sea] [--crop Y0,Y1,X0,X1] [--local]
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
from projection_sheets import _grid
from quality_projection import CASES, CLIPS

MAGENTA = np.array([255, 0, 255], np.uint8)


def play(db: str, method: str) -> np.ndarray:
    from dynatex.player.modes.lds import LDSPlayer
    from dynatex.player.modes.mixture import MixturePlayer

    cls = LDSPlayer if method == "lds" else MixturePlayer
    with cls(db, seed=1, backend="numpy") as p:
        p.advance(1000)
        return np.stack([p.next_frame() for _ in range(64)])


def outside_of(frames: np.ndarray, src: np.ndarray, local: bool) -> np.ndarray:
    """Per pixel of ``frames``: its colour is outside the source's set (or its region's, ``local``)."""
    from dynatex.analyzer.metrics import colour_set
    from dynatex.analyzer.metrics.gamut import LOCAL_BLOCK, _region_ids, colour_bins, local_colour_sets

    if not local:
        return ~colour_set(src)[colour_bins(frames)].reshape(frames.shape[:3])
    ids, _ = _region_ids(src.shape[1:3], LOCAL_BLOCK)
    keys = np.tile(ids, len(frames)) * 32**3 + colour_bins(frames)
    return ~local_colour_sets(src).reshape(-1)[keys].reshape(frames.shape[:3])


def run_case(
    name: str, before: str, after: str, outdir: str, crop: tuple[int, int, int, int], local: bool = False
) -> dict:
    from PIL import Image

    from dynatex.analyzer.video import load_clip_path

    clip_file, method, *_ = CASES[name]
    src = load_clip_path(os.path.join(CLIPS, clip_file)).frames
    a, b = play(os.path.join(before, f"{name}.h5"), method), play(os.path.join(after, f"{name}.h5"), method)
    outside_a, outside_b = outside_of(a, src, local), outside_of(b, src, local)
    worst = np.argsort(outside_a.reshape(len(a), -1).sum(axis=1))[::-1][:3]
    marked = a.copy()
    marked[outside_a] = MAGENTA
    rows = [[src[(5 * k) % len(src)], a[k], b[k], marked[k]] for k in worst]
    Image.fromarray(_grid(rows, 1)).save(os.path.join(outdir, f"{name}_gamut.png"))
    y0, y1, x0, x1 = crop
    for scale, suffix in ((1, "crop"), (4, "crop4x")):
        cut = [[f[y0:y1, x0:x1] for f in row] for row in rows]
        Image.fromarray(_grid(cut, scale)).save(os.path.join(outdir, f"{name}_{suffix}.png"))
    h, w = src.shape[1:3]
    size = (round(w * 1080 / h), 1080)
    for tag, frames in (("before", a), ("after", b)):
        canvas = np.zeros((1080, 1920, 3), np.uint8)
        big = np.asarray(Image.fromarray(frames[worst[0]]).resize(size, Image.BILINEAR))
        x = (1920 - size[0]) // 2
        canvas[:, max(x, 0) : max(x, 0) + min(size[0], 1920)] = big[:, max(-x, 0) : max(-x, 0) + min(size[0], 1920)]
        Image.fromarray(canvas).save(os.path.join(outdir, f"{name}_1080_{tag}.png"))
    return {
        "clip": name,
        "frames": [int(k) for k in worst],
        "outside_before": float(outside_a.mean()),
        "outside_after": float(outside_b.mean()),
        "changed_pixels": float((a != b).any(axis=-1).mean()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("outdir")
    ap.add_argument("--clips", default="flag")
    ap.add_argument("--crop", default="20,140,60,300", help="Y0,Y1,X0,X1 of the region sheet")
    ap.add_argument("--local", action="store_true", help="colours the pixel's region never had")
    args = ap.parse_args()
    os.makedirs(args.outdir, exist_ok=True)
    crop = tuple(int(v) for v in args.crop.split(","))
    for name in args.clips.split(","):
        print(json.dumps(run_case(name, args.before, args.after, args.outdir, crop, args.local)), flush=True)


if __name__ == "__main__":
    main()
