"""Issue 17's "must show" figures for mode ``tiles``: does the output look like the texture?

For each clip of ``../shared/data/clips`` (grass, sea, fountain, flag, steam, flames), analyze
with ``--methods tiles`` (the analyzer's default construction, or ``--construction``), play
``--frames`` frames (default 120) at twice the analysed source size in each dimension, and
measure:

- lattice prominence of the output at the player's cell lattice (``lattice_prominence``),
  beside the source's at the same lags;
- grid seam: ``seam_visibility`` across the cell lattice (``grid_labels``);
- wrap discontinuity: ``temporal_discontinuity`` of tile 0 played twice, at the loop's wrap;
- tone: the output's mean RGB under a tone target of the clip's own mean times
  (1.15, 1.0, 0.85) (a warmer colour every clip can reach), largest relative error;
- analysis time.

With ``--sheets DIR`` it writes ``DIR/PREFIX_CLIP.png`` contact sheets (source frames beside
output frames, ``dynatex.analyzer.sheet.contact_sheet``) to look at.

The 1280x720 flames clip is analysed at 320x180 (its output at 640x360), steam at its
128x128.

Usage::

    python benchmarks/lattice_tiles.py [--clips grass,sea] [--construction ring] \\
        [--sheets /tmp/sheets --prefix before] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip, metrics
from dynatex.analyzer.sheet import contact_sheet
from dynatex.analyzer.tiles import learn_tiles
from dynatex.player.modes.tiles import TilesPlayer
from dynatex.tiledb import DatabaseWriter
from dynatex.tiledb.tiles import CONSTRUCTIONS

FILES = {
    "grass": ("grass_straw_wind_dyntex.avi", {}),
    "sea": ("water_sea_waves_dyntex.avi", {}),
    "fountain": ("fountain_dyntex_6486110.avi", {}),
    "flag": ("flag_wind_dyntex_571c110.avi", {}),
    "steam": ("steam_vapour_pot_128px.avi", {}),
    "flames": ("fire_flames_720p.mp4", {"size": (180, 320)}),
}
TONE_FACTORS = np.array([1.15, 1.0, 0.85])


def measure(
    name: str, *, n_out: int, backend: str, workdir: str, construction: str | None, sheets: str | None, prefix: str
) -> dict:
    file, opts = FILES[name]
    clip = load_clip(str(CLIPS / file), **opts)
    frames = clip.frames
    res: dict = {"clip": name, "source": f"{frames.shape[2]}x{frames.shape[1]}x{frames.shape[0]}"}
    t0 = time.perf_counter()
    model = learn_tiles(frames, **({"construction": construction} if construction else {}))
    res["analysis_s"] = round(time.perf_counter() - t0, 1)
    res["construction"] = model.info["construction"]
    th, tw = model.tile_size
    res.update(tile=f"{tw}x{th}", loop=model.loop_length, n_tiles=model.n_tiles)
    path = os.path.join(workdir, f"{name}.h5")
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture(name, clip.source_info())
        w.put_method(name, "tiles", model)
    H, W = 2 * frames.shape[1], 2 * frames.shape[2]
    with TilesPlayer(path, backend=backend, size=(H, W), seed=1) as p:
        out = np.stack([p.next_frame() for _ in range(n_out)])
        ch, cw = p.tile_size
    res["output"] = f"{W}x{H}x{n_out}"
    prom, lags = metrics.lattice_prominence(out, (ch, cw), per_lag=True)
    res["lattice_prominence"] = prom
    res["lattice_lags"] = {k: round(v, 3) for k, v in lags.items()}
    res["lattice_prominence_source"] = metrics.lattice_prominence(frames, (ch, cw))
    res["seam_grid"] = float(metrics.seam_visibility(out, metrics.grid_labels((H, W), (ch, cw))).mean())
    tile = model.tiles[0]
    res["wrap_discontinuity"] = float(
        metrics.temporal_discontinuity(np.concatenate([tile, tile]), [model.loop_length], source=frames)[0]
    )
    target = np.clip(frames.reshape(-1, 3).mean(axis=0) * TONE_FACTORS, 1, 254)
    with TilesPlayer(path, backend=backend, size=(H, W), seed=1, tone=tuple(target)) as p:
        acc = np.zeros(3)
        for _ in range(n_out):
            acc += p.next_frame().reshape(-1, 3).mean(axis=0)
    mean = acc / n_out
    res["tone_target"] = [round(float(v), 2) for v in target]
    res["tone_mean"] = [round(float(v), 2) for v in mean]
    res["tone_max_rel_error"] = float(np.max(np.abs(mean - target) / target))
    if sheets:
        os.makedirs(sheets, exist_ok=True)
        contact_sheet(
            frames,
            out,
            os.path.join(sheets, f"{prefix}_{name}.png"),
            title=f"tiles ({res['construction']}, cells {cw}x{ch})",
        )
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--clips", default=",".join(FILES), help=f"comma-separated subset of {', '.join(FILES)}")
    ap.add_argument("--backend", default="auto", choices=("auto", "opencl", "numpy"))
    ap.add_argument(
        "--construction", default=None, choices=CONSTRUCTIONS, help="tile construction (default: the analyzer's)"
    )
    ap.add_argument("--sheets", default=None, help="folder for contact sheets")
    ap.add_argument("--prefix", default="sheet", help="file name prefix of the contact sheets")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.clips.split(","):
            r = measure(
                name,
                n_out=args.frames,
                backend=args.backend,
                workdir=tmp,
                construction=args.construction,
                sheets=args.sheets,
                prefix=args.prefix,
            )
            results.append(r)
            print(json.dumps(r), file=sys.stderr, flush=True)
    print(
        "| clip | construction | cells | loop | tiles | lattice prominence (source) | grid seam | wrap | "
        "tone error | analysis s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        lp, ls = (
            ("n/a" if v is None else f"{v:.3f}") for v in (r["lattice_prominence"], r["lattice_prominence_source"])
        )
        print(
            f"| {r['clip']} | {r['construction']} | {r['tile']} | {r['loop']} | {r['n_tiles']} | "
            f"{lp} ({ls}) | {r['seam_grid']:.3f} | {r['wrap_discontinuity']:.2f} | "
            f"{100 * r['tone_max_rel_error']:.2f}% | {r['analysis_s']} |"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
