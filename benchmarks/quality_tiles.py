"""Issue 5's "must show" quality figures for mode ``tiles`` (metrics from ``analyzer/metrics/``).

For each clip: analyze with ``--methods tiles``, play ``--frames`` frames at ``--size``, then

- seam visibility across the tile lattice (``seam_visibility`` with ``grid_labels``), beside
  the same figure for *uncut* rectangular blocks of the same size taken at random places
  and times of the source clip and laid out on the same lattice; and across the lattice
  plus every tile's ring cut (``seam_tiles_and_ring_cuts``);
- temporal wrap discontinuity of the loop: ``temporal_discontinuity`` of the primary tile
  played twice, at the wrap frame and at every frame of the per-pixel transition (the
  worst is reported), against the source's median frame step;
- repetition: ``repetition_lag`` of the output normalised by its own median frame step
  (None = no repeat up to ``frames - 10``), and the profile at the loop length; in space,
  ``lattice_correlation`` of the output at the tile size beside the source's at the same lags;
- mixing (two textures, label map "halves" with border tiles): seam visibility across the
  texture border over seam visibility across tile borders inside one texture, measured at
  the minimum cut itself (``source_class_map(strict=True)``) and where the dominant texture
  changes inside the fade (``source_class_map()``);
- tone: output mean RGB (over the whole run) against a target colour.

Usage::

    python benchmarks/quality_tiles.py [--frames 300] [--size 1280x720] [--json out.json]
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
from dynatex.analyzer.tiles import learn_tiles
from dynatex.player.modes.tiles import TilesPlayer
from dynatex.tiledb import DatabaseWriter
from dynatex.tiledb.tiles import CONSTRUCTIONS


def generated_clip(t: int = 250, h: int = 288, w: int = 352, seed: int = 0) -> np.ndarray:
    """Travelling waves plus moving noise blobs: a stochastic generated dynamic texture."""
    rng = np.random.default_rng(seed)
    tt, yy, xx = np.meshgrid(np.arange(t), np.arange(h), np.arange(w), indexing="ij", sparse=True)
    img = np.zeros((t, h, w), np.float32)
    for period, kx, ky in ((23.0, 0.21, 0.07), (13.0, -0.05, 0.17), (31.0, 0.11, -0.13)):
        img += np.sin(2 * np.pi * tt / period + kx * xx + ky * yy).astype(np.float32)
    img = 128 + 35 * img / 3 + rng.normal(0, 6, img.shape).astype(np.float32)
    g = np.clip(img, 0, 255).astype(np.uint8)
    return np.stack(
        [g, np.clip(g * 0.7 + 40, 0, 255).astype(np.uint8), np.clip(255 - g * 0.8, 0, 255).astype(np.uint8)], axis=3
    )


def uncut_blocks(
    frames: np.ndarray, shape: tuple[int, int], tile: tuple[int, int], n_out: int, seed: int = 0
) -> np.ndarray:
    """Output of the same lattice filled with uncut blocks from random places and start times."""
    rng = np.random.default_rng(seed)
    t, h, w = frames.shape[:3]
    th, tw = tile
    H, W = shape
    gh, gw = -(-H // th), -(-W // tw)
    out = np.empty((n_out, gh * th, gw * tw, 3), np.uint8)
    for i in range(gh):
        for j in range(gw):
            y, x = rng.integers(0, h - th + 1), rng.integers(0, w - tw + 1)
            s = rng.integers(0, t)
            idx = (s + np.arange(n_out)) % t
            out[:, i * th : (i + 1) * th, j * tw : (j + 1) * tw] = frames[idx, y : y + th, x : x + tw]
    return out[:, :H, :W]


def measure(
    name: str,
    frames: np.ndarray,
    *,
    size: tuple[int, int],
    n_out: int,
    backend: str,
    workdir: str,
    mix: np.ndarray | None = None,
    construction: str | None = None,
) -> dict:
    res: dict = {"clip": name, "source": list(frames.shape)}
    t0 = time.perf_counter()
    model = learn_tiles(
        frames,
        mix=[mix] if mix is not None else (),
        construction=construction if construction and mix is None else "ring",
    )
    res["construction"] = model.info["construction"]
    res["analysis_s"] = round(time.perf_counter() - t0, 2)
    th, tw = model.tile_size
    res.update(tile=f"{tw}x{th}", loop=model.loop_length, n_tiles=model.n_tiles)
    path = os.path.join(workdir, f"{name}.h5")
    clip = load_clip(frames)
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture(name, clip.source_info())
        w.put_method(name, "tiles", model)
    H, W = size
    with TilesPlayer(path, backend=backend, size=size, seed=1) as p:
        out = np.stack([p.next_frame() for _ in range(n_out)])
        arrangement = p.arrangement.copy()
    labels = metrics.grid_labels((H, W), (th, tw))
    res["seam_tiles"] = float(metrics.seam_visibility(out, labels).mean())
    # the lattice and every tile's ring cut (where its mask leaves 255) as boundaries
    yy, xx = np.mgrid[0:H, 0:W]
    strip = model.masks[arrangement[yy // th, xx // tw], yy % th, xx % tw] == 255
    res["seam_tiles_and_ring_cuts"] = float(metrics.seam_visibility(out, labels * 2 + strip).mean())
    blocks = uncut_blocks(frames, (H, W), (th, tw), n_out)
    res["seam_uncut_blocks"] = float(metrics.seam_visibility(blocks, labels).mean())
    # loop wrap: the primary tile played twice
    tile = model.tiles[0]
    twice = np.concatenate([tile, tile])
    L, o = model.loop_length, int(model.info["transition"])
    events = [L] + [L + j for j in range(1, o)]
    disc = metrics.temporal_discontinuity(twice, events, source=frames)
    res["wrap_discontinuity"] = float(disc[0])
    res["transition_discontinuity_max"] = float(disc.max())
    # Normalised by the output's own median step: normalising by the source's would compare
    # thumbnails of a 1280x720 output with those of a 352x288 clip (the larger frame averages
    # more pixels into each thumbnail pixel and so looks calmer).
    max_lag = n_out - 10
    prof = metrics.repetition_profile(out, max_lag=max_lag)
    res["repetition_lag"] = metrics.repetition_lag(out, max_lag=max_lag)
    res["repetition_min_profile"] = float(prof.min())
    res["repetition_at_loop"] = float(prof[model.loop_length - 1]) if model.loop_length <= max_lag else None
    res["lattice_correlation"] = [round(v, 3) for v in metrics.lattice_correlation(out[::10], (th, tw))]
    res["lattice_correlation_source"] = [round(v, 3) for v in metrics.lattice_correlation(frames[::10], (th, tw))]
    if mix is not None:
        for tone in (None, "consensus"):
            with TilesPlayer(path, backend=backend, size=size, seed=1, labels="halves", tone=tone) as p:
                mixed = np.stack([p.next_frame() for _ in range(min(n_out, 60))])
                border = p.source_class_map()  # where the dominant texture changes
                cut = p.source_class_map(strict=True)  # the minimum cut, before feathering
                xb = int(np.argmax(p.labels[0] == 1)) * tw  # first cell of the second texture
            inside = metrics.grid_labels((H, xb), (th, tw))
            key = "" if tone is None else "_tone"
            res["mix_seam_texture_border" + key] = float(metrics.seam_visibility(mixed, border).mean())
            res["mix_seam_at_cut" + key] = float(metrics.seam_visibility(mixed, cut).mean())
            res["mix_seam_inside" + key] = float(metrics.seam_visibility(mixed[:, :, :xb], inside).mean())
            res["mix_ratio" + key] = res["mix_seam_texture_border" + key] / res["mix_seam_inside" + key]
            res["mix_ratio_at_cut" + key] = res["mix_seam_at_cut" + key] / res["mix_seam_inside" + key]
    target = np.array([150.0, 120.0, 90.0])
    with TilesPlayer(path, backend=backend, size=size, seed=1, tone=tuple(target)) as p:
        acc = np.zeros(3)
        for _ in range(n_out):
            acc += p.next_frame().reshape(-1, 3).mean(axis=0)
    mean = acc / n_out
    res["tone_target"] = target.tolist()
    res["tone_mean"] = [round(float(v), 2) for v in mean]
    res["tone_max_rel_error"] = float(np.max(np.abs(mean - target) / target))
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--backend", default="opencl", choices=("opencl", "numpy"))
    ap.add_argument("--json", default=None)
    ap.add_argument(
        "--construction",
        default=None,
        choices=CONSTRUCTIONS,
        help="tile construction of the single-texture runs (default: the analyzer's, ring)",
    )
    ap.add_argument(
        "--clips",
        default="grass,water,generated,grass+water",
        help="comma-separated subset of grass, water, generated, grass+water (mixing)",
    )
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    size = (h, w)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        grass = load_clip(str(CLIPS / "grass_straw_wind_dyntex.avi")).frames
        water = load_clip(str(CLIPS / "water_sea_waves_dyntex.avi")).frames
        runs = {
            "grass": (grass, None),
            "water": (water, None),
            "generated": (generated_clip(), None),
            "grass+water": (grass, water),
        }
        for name in args.clips.split(","):
            frames, mix = runs[name]
            r = measure(
                name.replace("+", "_"),
                frames,
                size=size,
                n_out=args.frames,
                backend=args.backend,
                workdir=tmp,
                mix=mix,
                construction=args.construction,
            )
            results.append(r)
            print(json.dumps(r), file=sys.stderr)
    print(
        "| clip | construction | tile | loop | seam (tiles; with ring cuts) | seam (uncut blocks) | wrap disc. | "
        "worst transition | repetition lag (min profile) | lattice corr. y/x (source) | "
        "mix border/inside (at cut, in fade) | tone error | analysis s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        mixr = (
            (
                f"cut {r['mix_ratio_at_cut']:.2f} ({r['mix_ratio_at_cut_tone']:.2f} toned), fade "
                f"{r['mix_ratio']:.2f} ({r['mix_ratio_tone']:.2f} toned)"
            )
            if "mix_ratio" in r
            else "-"
        )
        lat, lsrc = r["lattice_correlation"], r["lattice_correlation_source"]
        print(
            f"| {r['clip']} | {r['construction']} | {r['tile']} | {r['loop']} | {r['seam_tiles']:.3f}; "
            f"{r['seam_tiles_and_ring_cuts']:.3f} | {r['seam_uncut_blocks']:.2f} | "
            f"{r['wrap_discontinuity']:.2f} | {r['transition_discontinuity_max']:.2f} | {r['repetition_lag']} "
            f"({r['repetition_min_profile']:.2f}) | {lat[0]:.2f}/{lat[1]:.2f} ({lsrc[0]:.2f}/{lsrc[1]:.2f}) | "
            f"{mixr} | {100 * r['tone_max_rel_error']:.2f}% | {r['analysis_s']} |"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
