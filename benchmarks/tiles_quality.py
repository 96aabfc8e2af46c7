"""Mode tiles: what a large output looks like against its source, in figures and a contact sheet.

    python benchmarks/tiles_quality.py CLIP [--size 1920x1080] [--frames 24] [--sheet out.png] [--json]

Analyzes ``CLIP`` (tiles only, defaults), plays ``--frames`` frames at ``--size`` and prints:

- ``autocorr``: the largest normalised autocorrelation of a frame's mean-removed luma at any
  shift of at least 64 pixels (Chebyshev; up to half the frame), median over a few frames,
  for the output and for the source (the source's shifts start at a quarter of its shorter
  side when that is under 64 pixels, and stop at half its size). A
  torus laid edge to edge shows its period here (about 0.8); a texture without repetition
  stays near the source's figure.
- ``lattice``: :func:`dynatex.analyzer.metrics.lattice_prominence` at the stored tile size.
- ``seams``: :func:`dynatex.analyzer.metrics.seam_visibility` across the cell lattice.
- ``straight``: :func:`straight_edges` of output and source: straight-edged fragments (a
  mosaic of blocks) push the output's figure above the source's.

Run it with ``/work/main/.venv/bin/python`` for the figures before a change.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from dynatex.analyzer.metrics import grid_labels, lattice_prominence, seam_visibility
from dynatex.analyzer.sheet import contact_sheet
from dynatex.analyzer.tiles import learn_tiles
from dynatex.analyzer.video import load_clip_path
from dynatex.player.modes.tiles import TilesPlayer
from dynatex.tiledb import DatabaseWriter


def _luma(frame: np.ndarray) -> np.ndarray:
    g = frame[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    return g - g.mean()


def far_autocorrelation(frame: np.ndarray, min_shift: int = 64) -> float:
    """Largest normalised autocorrelation of ``frame``'s luma at shifts ``max(|dy|, |dx|) >= min_shift``
    (up to half the frame in each direction; zero-padded FFT, mean product over the overlap)."""
    g = _luma(frame)
    h, w = g.shape
    spec = np.fft.rfft2(g, (2 * h, 2 * w))
    ac = np.fft.irfft2(spec * np.conj(spec), (2 * h, 2 * w))
    dy = np.arange(h // 2 + 1)
    dx = np.arange(-(w // 2), w // 2 + 1)
    raw = ac[dy[:, None], dx[None, :] % (2 * w)]
    count = (h - dy)[:, None] * (w - np.abs(dx))[None, :]
    norm = raw / count / max(float((g * g).mean()), 1e-12)
    far = np.maximum(dy[:, None], np.abs(dx)[None, :]) >= min_shift
    return float(norm[far].max()) if far.any() else float("nan")


def straight_edges(frames: np.ndarray, run: int = 16) -> float:
    """How much of a clip's edge energy lies on straight vertical or horizontal lines.

    Per frame and direction, the luma gradient across the lines (``d/dx`` for vertical
    lines) is averaged along them over ``run`` pixels; a straight edge keeps its sign and
    sums up, a wavy or textured one cancels. The figure is the 99.5th percentile of the
    absolute run mean over the mean absolute gradient, the larger direction, median over
    frames. A mosaic of blocks with straight borders scores above its source.
    """
    vals = []
    k = np.ones(run) / run
    for f in frames:
        g = _luma(f)
        best = 0.0
        for grad, axis in ((np.diff(g, axis=1), 0), (np.diff(g, axis=0), 1)):
            sm = np.apply_along_axis(lambda v: np.convolve(v, k, mode="valid"), axis, grad)
            best = max(best, float(np.percentile(np.abs(sm), 99.5) / max(np.abs(grad).mean(), 1e-9)))
        vals.append(best)
    return float(np.median(vals))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clip")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--sheet", help="write a contact sheet (source beside output) here")
    ap.add_argument("--db", help="use (or write) this database instead of a temporary one")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.lower().split("x"))
    clip = load_clip_path(args.clip)
    src = clip.frames
    with tempfile.TemporaryDirectory() as tmp:
        db = args.db or str(Path(tmp) / "t.h5")
        if not Path(db).exists():
            model = learn_tiles(clip)
            with DatabaseWriter(db, overwrite=True) as wr:
                wr.put_texture("t", clip.source_info())
                wr.put_method("t", "tiles", model)
        with TilesPlayer(db, size=(h, w), seed=3) as p:
            out = np.stack([p.next_frame() for _ in range(args.frames)])
            cell = p.tile_size
    idx = np.unique(np.linspace(0, len(out) - 1, 4).round().astype(int))
    sidx = np.unique(np.linspace(0, len(src) - 1, 4).round().astype(int))
    src_shift = min(64, min(src.shape[1:3]) // 4)  # a clip under 256 px: a quarter of its side
    res = {
        "clip": Path(args.clip).name,
        "size": args.size,
        "cell": list(cell),
        "autocorr_out": float(np.median([far_autocorrelation(out[i]) for i in idx])),
        "autocorr_src": float(np.median([far_autocorrelation(src[i], src_shift) for i in sidx])),
        "src_shift": src_shift,
        "lattice": lattice_prominence(out, cell),
        "seams": float(np.median(seam_visibility(out[idx], grid_labels((h, w), cell)))),
        "straight_out": straight_edges(out[idx]),
        "straight_src": straight_edges(src[sidx]),
    }
    if args.sheet:
        contact_sheet(src, out, args.sheet, rows=2, title=f"tiles {args.size} {res['clip']}")
    if args.json:
        print(json.dumps(res))
    else:
        print("  ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in res.items()))


if __name__ == "__main__":
    main()
