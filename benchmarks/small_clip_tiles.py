"""Mode tiles on small clips: straight-edged fragments of the quilted torus against the source.

    python benchmarks/small_clip_tiles.py CLIP [CLIP ...] [--blocks default,24,40] [--scale 5]
        [--max-side 1024] [--frames 8] [--seeds 0] [--crop N] [--sheets DIR] [--json]

For every clip, every quilt block size in ``--blocks`` (``default``: the analyzer's own
choice, :func:`dynatex.analyzer.tiles.quilted.quilt_geometry`) and every quilt seed in
``--seeds`` (the lattice figure varies by about 0.03 between seeds), analyzes the clip (tiles only),
plays ``--frames`` frames at ``--scale`` times the clip's size (each side at most
``--max-side``; ``--crop N``: the clip's central ``N x N`` pixels instead, a small clip cut
from a large one) and prints:

- ``straight`` / ``straight_src``: :func:`tiles_quality.straight_edges` of output and source
  (the measure of ``benchmarks/stochastic_tiles.py``): a mosaic of straight-edged blocks
  scores above its source.
- ``lattice``: :func:`dynatex.analyzer.metrics.lattice_prominence` at the stored tile size.
- ``seams``: :func:`dynatex.analyzer.metrics.seam_visibility` across the cell lattice.
- ``scale``, ``block``, ``step``, ``cell``, ``period``: the clip's feature scale
  (:func:`dynatex.analyzer.tiles.feature_scale`) and the geometry the analysis chose from it.

``--sheets``: a contact sheet (source frames beside output frames) per clip and block.
Run it with ``/work/main/.venv/bin/python`` for the figures before a change.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from tiles_quality import straight_edges  # noqa: E402

from dynatex.analyzer.metrics import grid_labels, lattice_prominence, seam_visibility  # noqa: E402
from dynatex.analyzer.sheet import contact_sheet  # noqa: E402
from dynatex.analyzer.tiles import learn_tiles  # noqa: E402
from dynatex.analyzer.video import load_clip_path  # noqa: E402
from dynatex.player.modes.tiles import TilesPlayer  # noqa: E402
from dynatex.tiledb import DatabaseWriter  # noqa: E402


def figures(clip_path: str, block: int | None, seed: int, args: argparse.Namespace, folder: Path) -> dict:
    name = Path(clip_path).name
    clip = load_clip_path(clip_path)
    if args.crop:
        h, w = clip.frames.shape[1:3]
        y0, x0 = max(0, (h - args.crop) // 2), max(0, (w - args.crop) // 2)
        clip = replace(clip, frames=np.ascontiguousarray(clip.frames[:, y0 : y0 + args.crop, x0 : x0 + args.crop]))
    src = clip.frames
    h, w = src.shape[1:3]
    size = (min(args.scale * h, args.max_side), min(args.scale * w, args.max_side))
    model = learn_tiles(clip, tile=block, seed=seed)
    db = folder / f"{Path(clip_path).stem}_{args.crop}_{block or 'default'}.h5"
    with DatabaseWriter(db, overwrite=True) as wr:
        wr.put_texture("t", clip.source_info())
        wr.put_method("t", "tiles", model)
    with TilesPlayer(str(db), size=size, seed=3) as p:
        out = np.stack([p.next_frame() for _ in range(args.frames)])
        cell = p.tile_size
    idx = np.unique(np.linspace(0, len(out) - 1, 4).round().astype(int))
    sidx = np.unique(np.linspace(0, len(src) - 1, 4).round().astype(int))
    info = model.info
    res = {
        "clip": name,
        "blocks": "default" if block is None else str(block),
        "seed": seed,
        "scale": round(float(info.get("quilt_scale", float("nan"))), 1),
        "block": int(info["quilt_block"]),
        "step": int(info["quilt_step"]),
        "cell": int(info["tile_h"]),
        "period": f"{info['period_w']}x{info['period_h']}",
        "size": f"{size[1]}x{size[0]}",
        "straight": straight_edges(out[idx]),
        "straight_src": straight_edges(src[sidx]),
        "lattice": lattice_prominence(out, cell, max_frames=4),
        "seams": float(np.median(seam_visibility(out[idx], grid_labels(size, cell)))),
    }
    if args.sheets is not None:
        args.sheets.mkdir(parents=True, exist_ok=True)
        path = args.sheets / f"{Path(clip_path).stem}_{h}px_{res['size']}_block{res['block']}_seed{seed}.png"
        contact_sheet(src, out, str(path), rows=2, title=f"tiles {res['size']} block {res['block']} {name}")
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clips", nargs="+")
    ap.add_argument("--blocks", default="default", help="comma-separated block sizes; 'default' = the analyzer's")
    ap.add_argument("--scale", type=int, default=5)
    ap.add_argument("--max-side", type=int, default=1024)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--seeds", default="0", help="comma-separated quilt seeds")
    ap.add_argument("--crop", type=int, help="use the clip's central N x N pixels")
    ap.add_argument("--sheets", type=Path, help="write contact sheets here")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    blocks = [None if b == "default" else int(b) for b in args.blocks.split(",") if b]
    with tempfile.TemporaryDirectory() as tmp:
        for clip_path in args.clips:
            for block, seed in ((b, int(s)) for b in blocks for s in args.seeds.split(",")):
                res = figures(clip_path, block, seed, args, Path(tmp))
                if args.json:
                    print(json.dumps(res), flush=True)
                else:
                    text = (f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in res.items())
                    print("  ".join(text), flush=True)


if __name__ == "__main__":
    main()
