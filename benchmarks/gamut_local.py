"""Colours a place never had: the local out-of-gamut share (each 16 x 16 region's colour set,
:func:`~dynatex.analyzer.metrics.gamut.local_out_of_gamut_share`) of ``lds`` / ``mixture``
output beside the global one, against the source's own levels (each half against the other).

Per clip of ``quality_projection.py`` (its databases in DBDIR; analysed there when absent):
50 frames of warm-up, 300 measured (numpy), as the issue's tables; ``--variants`` plays the
texture as stored (``full``), without the detail (``nodetail``: the projection alone, no
per-pixel colour range) and without the colour clamp (``noclamp``: no ``gamut`` part).
``border_step`` (x, y): the mean luma step across the borders of the stored local sets' regions
over that across the lines halfway between them (1: no edge where two regions' sets meet; the
source's at its side, its codec's block grid alike at both).

    python benchmarks/gamut_local.py DBDIR [--clips flag,sea,fountain,grass,steam]
        [--variants full,nodetail,noclamp] [--block 16]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np
from quality_projection import CASES, CLIPS


def play(db: str, method: str, variant: str, warm: int = 50, frames: int = 300) -> np.ndarray:
    from dynatex.player.modes.lds import LDSPlayer
    from dynatex.player.modes.mixture import MixturePlayer

    cls = LDSPlayer if method == "lds" else MixturePlayer
    with cls(db, seed=1, backend="numpy") as p:
        if variant == "nodetail":
            p.detail_engine = None
        elif variant == "noclamp":
            for name in ("nearest", "local"):
                if hasattr(p.engine, name):
                    setattr(p.engine, name, None)
        for _ in range(warm):
            p.next_frame()
        return np.stack([p.next_frame() for _ in range(frames)])


def local_block(db: str, method: str) -> int | None:
    """The side of the local colour sets' regions as the player lays them out (None: none)."""
    from dynatex.player.modes.lds import LDSPlayer
    from dynatex.player.modes.mixture import MixturePlayer

    with (LDSPlayer if method == "lds" else MixturePlayer)(db, seed=1, backend="numpy") as p:
        local = getattr(p.engine, "local", None)
        return None if local is None else local.block


def border_step(frames: np.ndarray, block: int) -> tuple[float, float]:
    """Mean |step| of luma across the region borders (every ``block`` pixels) over that across
    the lines halfway between them, along x and along y."""
    f = frames[..., :3].astype(np.float32).mean(-1)
    dx, dy = np.abs(np.diff(f, axis=2)), np.abs(np.diff(f, axis=1))
    half = block // 2
    return (
        round(float(dx[:, :, block - 1 :: block].mean() / dx[:, :, half - 1 :: block].mean()), 3),
        round(float(dy[:, block - 1 :: block].mean() / dy[:, half - 1 :: block].mean()), 3),
    )


def main() -> None:
    from dynatex.analyzer.metrics import out_of_gamut_share, source_gamut_share
    from dynatex.analyzer.metrics.gamut import local_out_of_gamut_share, source_local_gamut_share
    from dynatex.analyzer.video import load_clip_path

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dbdir")
    ap.add_argument("--clips", default="flag,sea,fountain,grass,steam")
    ap.add_argument("--variants", default="full")
    ap.add_argument("--block", type=int, default=16)
    ap.add_argument("--save", action="store_true", help="keep each output as DBDIR/{clip}_{variant}.npy")
    args = ap.parse_args()
    for name in args.clips.split(","):
        clip_file, method, *extra = CASES[name]
        path = os.path.join(CLIPS, clip_file)
        db = os.path.join(args.dbdir, f"{name}.h5")
        if not os.path.exists(db):
            cmd = [sys.executable, "-m", "dynatex", "analyze", path, "-o", db, "--methods", method, "-q", *extra]
            subprocess.run(cmd, check=True)
        src = load_clip_path(path).frames
        row = {
            "clip": name,
            "source_global": source_gamut_share(src),
            "source_local": source_local_gamut_share(src, block=args.block),
        }
        block = local_block(db, method)
        if block is not None:
            row["source_border_step"] = border_step(src, block)
        for variant in args.variants.split(","):
            out = play(db, method, variant)
            if args.save:
                np.save(os.path.join(args.dbdir, f"{name}_{variant}.npy"), out)
            row[f"{variant}_global"] = out_of_gamut_share(out, src)
            row[f"{variant}_local"] = local_out_of_gamut_share(out, src, block=args.block)
            if block is not None:
                row[f"{variant}_border_step"] = border_step(out, block)
        print(json.dumps({k: (float(f"{v:.3g}") if isinstance(v, float) else v) for k, v in row.items()}), flush=True)


if __name__ == "__main__":
    main()
