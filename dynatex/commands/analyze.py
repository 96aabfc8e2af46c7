"""``dynatex analyze CLIP... -o DB.h5|FOLDER``: learn models from clips and store them.

One clip goes into ``DB.h5`` (other textures in it are kept). Several clips (paths, globs,
folders of clips, ``.txt`` lists) make one database per clip in the folder ``-o``, on
Dask with ``--scheduler``, optionally merged into one database with ``--merge``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from ..analyzer.methods import METHODS, get_method
from ..analyzer.quilt import DEFAULT_BLOCK as QUILT_BLOCK
from ..tiledb import DatabaseWriter
from ..tiledb.schema import texture_name_from
from ..tiledb.tiles import CONSTRUCTIONS as TILE_CONSTRUCTIONS
from ._common import (
    MAX_COUNT,
    MAX_SIDE,
    Number,
    Numbers,
    UsageError,
    count,
    load_clip_arg,
    positive_int,
    seed,
    size_arg,
    tqdm_progress,
)

_N = Number(int, 1, MAX_COUNT)


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser("analyze", help="learn models from clips and write tile databases",
                       description="Read a clip, run the chosen methods and write them into a tile "
                                   "database (other textures already in it are kept). Given several clips "
                                   "(or a glob, a folder of clips, a .txt list), write one database per clip "
                                   "into the folder -o, skipping clips whose database is already complete, "
                                   "and print a summary; the exit code is 2 when some clips failed.")
    p.add_argument("clip", nargs="+",
                   help="video file, folder of images, or .npy array (T, H, W[, C]) uint8; several clips, "
                        "globs, folders of clips or .txt files listing clips analyse a corpus")
    p.add_argument("-o", "--output", required=True,
                   help="tile database to create or update (.h5); with several clips, the folder of their databases")
    p.add_argument("--name", help="texture name: any letters, up to 64 characters, no '/' (default: the clip's file "
                                  "name without extension; one clip only)")
    p.add_argument("--methods", default="lds",
                   help=f"comma-separated methods to run: {', '.join(METHODS)} (default: lds)")
    p.add_argument("--overwrite", action="store_true",
                   help="start a new database instead of updating one; with several clips, analyse every clip "
                        "again (even those whose database is complete) and start --merge afresh")
    g = p.add_argument_group("corpus and scale")
    g.add_argument("--scheduler", default="none", metavar="none|local|tcp://HOST:PORT",
                   help="where clips run: none (in this process, default), local (a Dask LocalCluster on this "
                        "machine) or the address of a running Dask scheduler; needs dynatex[dask]")
    g.add_argument("--workers", type=positive_int, default=None,
                   help="workers of --scheduler local (default: CPU cores, at most one per clip); BLAS threads "
                        "are split between them")
    g.add_argument("--merge", default=None, metavar="OUT.h5",
                   help="afterwards, gather every clip's texture into this database (atomically)")
    g.add_argument("--max-memory", default=None, metavar="SIZE",
                   help="bound per clip, e.g. 2GB: the clip is spilled to disk and lds and mixture learn out of "
                        "core; other methods need the frames to fit")
    g.add_argument("--spill-dir", default=None, metavar="DIR",
                   help="folder of the clip copies --max-memory spills (default: the system's temporary folder)")
    g = p.add_argument_group("clip input")
    g.add_argument("--start", type=count, default=0, help="first frame (default 0)")
    g.add_argument("--stop", type=positive_int, default=None, help="stop before this frame")
    g.add_argument("--step", type=positive_int, default=1, help="take every STEP-th frame")
    g.add_argument("--crop", type=_crop_arg, default=None, metavar="X,Y,W,H", help="keep this region")
    g.add_argument("--resize", type=size_arg, default=None, metavar="WxH", help="resize frames")
    g.add_argument("--grey", action="store_true", help="analyse in grey levels instead of colour")
    g = p.add_argument_group("lds")
    g.add_argument("--n", type=_n_arg, default=50, help=f"state order, {_N.describe()}, or 'auto' (default 50)")
    g.add_argument("--k", type=positive_int, default=None, help="noise rank (default n)")
    g.add_argument("--energy", type=Number(float, 0.0, 1.0, low_open=True), default=0.9,
                   help="variance kept by --n auto, in %(type)s (default 0.9)")
    g.add_argument("--svd", choices=("auto", "gram", "randomized"), default="auto")
    g.add_argument("--max-radius", type=Number(float, 0.0, 1.0, low_open=True, high_open=True), default=0.995,
                   help="largest pole magnitude, in %(type)s (default 0.995)")
    g = p.add_argument_group("turnpoints")
    g.add_argument("--tp-n", type=positive_int, default=4, help="mirrored frame pairs of the symmetry test (default 4)")
    g.add_argument("--tp-s", type=count, default=1, help="binomial smoothness, 0 <= s < n/2 (default 1)")
    g.add_argument("--tp-r", type=positive_int, default=4, help="turn points are more than R frames apart (default 4)")
    g.add_argument("--tp-min-symmetry", type=Number(float, 0.0, 1.0, high_open=True), default=0.3,
                   help="weakest turn point, in %(type)s (default 0.3)")
    g.add_argument("--tp-max-cost", type=Number(float, 0.0, 1e6, low_open=True), default=2.0,
                   help="drop transitions costlier than this many median frame steps, in %(type)s (default 2)")
    g.add_argument("--tp-plot", default=None, metavar="PNG",
                   help="write a plot of the symmetry curve, turn points and probabilities")
    g = p.add_argument_group("mixture")
    g.add_argument("--mix-components", type=positive_int, default=3, help="PPCA components S (default 3)")
    g.add_argument("--mix-dim", type=positive_int, default=10, help="dimension d of each component (default 10)")
    g.add_argument("--mix-global-dim", type=positive_int, default=None, help="global coordinates D (default d)")
    g.add_argument("--mix-pca-dim", type=positive_int, default=50, help="reduced PCA space (default 50)")
    g.add_argument("--mix-neighbors", type=positive_int, default=12, help="LLE neighbours K (default 12)")
    g.add_argument("--mix-pmax", type=positive_int, default=None,
                   help="largest AR order tried (default 5, or less when the clip is short)")
    g = p.add_argument_group("tiles")
    g.add_argument("--tile", type=_tile_arg, default=None, metavar="N or WxH",
                   help="tile size in pixels (default: from the dominant spatial period); with the quilted "
                        "construction the quilt block size N (default a third of the shorter side)")
    g.add_argument("--tiles-construction", choices=TILE_CONSTRUCTIONS, default=None,
                   help="quilted: one large seamless torus quilted from the clip, cut into cells laid out in "
                        "order, no lattice (default for one texture); ring: tiles share one boundary ring and "
                        "join in any arrangement (default with --tiles-mix, --tiles-n or --tiles-ring); wang: "
                        "edge-coloured tiles that join where colours match (one texture only)")
    g.add_argument("--tiles-period", type=_tile_arg, default=None, metavar="WxH",
                   help="quilted: period of the torus (default at least 512 and twice the clip per side)")
    g.add_argument("--tiles-n", type=Number(int, 1, 64), default=None,
                   help="tiles per texture with the ring construction, %(type)s (default 4)")
    g.add_argument("--tiles-edge-colours", type=Number(int, 2, 4), default=2,
                   help="Wang edge colours per direction, %(type)s (default 2: 8 tiles)")
    g.add_argument("--tiles-min-loop", type=Number(int, 2, MAX_COUNT), default=32,
                   help="shortest loop in frames (default 32)")
    g.add_argument("--tiles-max-loop", type=positive_int, default=None, help="longest loop (default: the clip)")
    g.add_argument("--tiles-transition", type=positive_int, default=8,
                   help="frames over which the per-pixel temporal transitions spread (default 8)")
    g.add_argument("--tiles-ring", type=Number(int, 2, MAX_SIDE), default=None,
                   help="width of the band of the shared ring cuts (default tile/10)")
    g.add_argument("--tiles-flow-gain", type=Number(float, 0.0, 10.0), default=0.5,
                   help="extra cut freedom per pixel/frame of optical flow, in %(type)s (default 0.5, 0 = off)")
    g.add_argument("--tiles-mix", action="append", default=[], metavar="CLIP",
                   help="another texture to mix with (repeatable): cut to the same tiles, with border tiles")
    g.add_argument("--tiles-names", default=None, metavar="A,B,...",
                   help="class names of the main and the --tiles-mix textures (default main,mix1,...)")
    g = p.add_argument_group("quilt (time-varying textures)")
    g.add_argument("--quilt-size", type=size_arg, default=None, metavar="WxH",
                   help="output canvas (default: twice the clip's width and height)")
    g.add_argument("--quilt-block", type=_tile_arg, default=QUILT_BLOCK, metavar="N or WxH",
                   help=f"block size; elongated blocks (e.g. 16x64) suit stretching features (default {QUILT_BLOCK})")
    g.add_argument("--quilt-overlap", type=positive_int, default=None, help="block overlap (default 5/16 of the block)")
    g.add_argument("--quilt-rank", type=positive_int, default=15, help="SVD rank of the comparisons (default 15)")
    g.add_argument("--quilt-tolerance", type=Number(float, 0.0, 1e6), default=0.1,
                   help="pick among candidates within (1 + T) of the best error, T in %(type)s (default 0.1)")
    g.add_argument("--quilt-feather", type=Number(int, 0, MAX_SIDE), default=None,
                   help="cross-fade half-width across cuts (default overlap/2, 0 = hard cuts)")
    g.add_argument("--quilt-lowpass", type=Number(float, 0.0, float(MAX_SIDE), low_open=True), default=None,
                   metavar="SIGMA", help="low-pass gain normalisation with this Gaussian sigma in pixels, "
                                         "in %(type)s (default off)")
    g.add_argument("--quilt-restore-gradient", action="store_true",
                   help="with --quilt-lowpass: keep the source's low-frequency gradient instead of flattening it")
    g.add_argument("--quilt-seed", type=seed, default=0, help="seed of the random block choices (default 0)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars or summary")
    return p


def _crop_arg(text: str) -> tuple[int, int, int, int]:
    x, y, w, h = Numbers(Number(int, 0, MAX_COUNT), 4, "X,Y,W,H")(text)
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"crop {text!r}: width and height must be at least 1")
    return x, y, w, h


def _n_arg(text: str) -> int | str:
    return "auto" if text.strip().lower() == "auto" else _N(text)


def method_params(name: str, args: argparse.Namespace) -> dict:
    """Keyword arguments of method ``name``'s learn function, from the command line."""
    if name == "lds":
        return {"n": args.n, "k": args.k, "energy": args.energy, "svd": args.svd, "max_radius": args.max_radius}
    if name == "mixture":
        return {"components": args.mix_components, "dim": args.mix_dim, "global_dim": args.mix_global_dim,
                "pca_dim": args.mix_pca_dim, "neighbors": args.mix_neighbors, "pmax": args.mix_pmax}
    if name == "turnpoints":
        return {"n": args.tp_n, "s": args.tp_s, "r": args.tp_r, "min_symmetry": args.tp_min_symmetry,
                "max_cost": args.tp_max_cost}
    if name == "tiles":
        mix = []
        for path in args.tiles_mix:
            mix.append(load_clip_arg(path, stop=args.stop, step=args.step, size=args.resize,
                                     color=not args.grey).frames)
        names = None if args.tiles_names is None else [n.strip() for n in args.tiles_names.split(",")]
        return {"tile": args.tile, "construction": args.tiles_construction, "n_tiles": args.tiles_n,
                "edge_colours": args.tiles_edge_colours, "min_loop": args.tiles_min_loop,
                "max_loop": args.tiles_max_loop, "transition": args.tiles_transition, "ring": args.tiles_ring,
                "flow_gain": args.tiles_flow_gain, "mix": mix, "names": names,
                **({} if args.tiles_period is None else {"period": _pair(args.tiles_period)})}
    if name == "quilt":
        return {"size": args.quilt_size, "block": args.quilt_block, "overlap": args.quilt_overlap,
                "rank": args.quilt_rank, "tolerance": args.quilt_tolerance, "feather": args.quilt_feather,
                "lowpass": args.quilt_lowpass, "restore_gradient": args.quilt_restore_gradient,
                "seed": args.quilt_seed}
    return {}


def _pair(v) -> tuple[int, int]:
    return (v, v) if isinstance(v, int) else v


def _tile_arg(text: str):
    side = Number(int, 1, MAX_SIDE)
    parts = [side.parse(v) for v in text.lower().split("x")]
    if len(parts) not in (1, 2) or any(p is None for p in parts):
        raise argparse.ArgumentTypeError(f"expected N or WxH, each side an integer in {side}, not {text!r}")
    return parts[0] if len(parts) == 1 else (parts[1], parts[0])    # WxH -> (h, w)


def run(args: argparse.Namespace) -> int:
    from ..analyzer.corpus import find_clips
    from ..analyzer.stream import parse_bytes
    names = [m.strip() for m in args.methods.split(",") if m.strip()]
    if not names:
        raise UsageError("--methods names no method")
    methods = [get_method(m) for m in names]
    max_memory = None if args.max_memory is None else _parse_bytes_arg(parse_bytes, args.max_memory)
    clips = find_clips(args.clip)
    corpus = (len(clips) > 1 or len(args.clip) > 1 or args.scheduler != "none" or args.merge is not None
              or os.path.isdir(args.output))
    if corpus:
        return _run_corpus(args, clips, names, max_memory)
    return _run_one(args, clips[0], methods, max_memory)


def _parse_bytes_arg(parse, text: str) -> int:
    try:
        return parse(text)
    except ValueError as exc:
        raise UsageError(f"--max-memory: {exc}") from None


def _load_options(args: argparse.Namespace) -> dict:
    return {"start": args.start, "stop": args.stop, "step": args.step, "crop": args.crop, "size": args.resize,
            "color": not args.grey}


def _run_one(args: argparse.Namespace, clip_path: str, methods, max_memory: int | None) -> int:
    from ..analyzer.corpus import learn_into
    stem = os.path.splitext(os.path.basename(os.path.normpath(clip_path)))[0]
    texture = args.name or texture_name_from(stem)
    show = not args.quiet
    t0 = time.perf_counter()

    def report(name: str, model, seconds: float) -> None:
        if name == "turnpoints" and args.tp_plot:
            from ..analyzer.turnpoints import plot_turnpoints
            plot_turnpoints(model, args.tp_plot, title=texture)
        if show:
            print(f"{name}: {_summary(name, model)} ({seconds:.1f} s)", file=sys.stderr)
        if name == "tiles":
            from ..analyzer.tiles import stationarity_warning
            warning = stationarity_warning(model.info)
            if warning:
                print(f"dynatex: warning: {texture}: {warning}", file=sys.stderr)

    params = {m.name: method_params(m.name, args) for m in methods}
    # Open (and so validate) an existing database before the long work.
    with DatabaseWriter(args.output, overwrite=args.overwrite) as writer:
        source = learn_into(writer, texture, clip_path, [m.name for m in methods], params=params,
                            load=_load_options(args), max_memory=max_memory, spill_dir=args.spill_dir,
                            isolate=True, progress=lambda stage: tqdm_progress(stage, show), on_model=report)
    if show:
        s = source
        print(f"wrote texture {texture!r} ({s.width}x{s.height}x{s.channels}, {s.n_frames} frames, methods "
              f"{', '.join(m.name for m in methods)}) to {args.output} in {time.perf_counter() - t0:.1f} s")
    return 0


def _run_corpus(args: argparse.Namespace, clips: list[str], names: list[str], max_memory: int | None) -> int:
    from ..analyzer.corpus import FAILED, analyze_corpus, format_table
    for flag, value in (("--name", args.name), ("--tiles-mix", args.tiles_mix), ("--tp-plot", args.tp_plot)):
        if value:
            raise UsageError(f"{flag} works with one clip only, not a corpus of {len(clips)}")
    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise UsageError(f"-o {args.output}: with several clips -o names a folder for their databases, "
                         f"and this is a file")
    if args.merge is not None and os.path.isdir(args.merge):
        raise UsageError(f"--merge {args.merge}: is a folder, not a database file")
    if args.merge is not None and not os.path.isdir(os.path.dirname(os.path.abspath(args.merge))):
        raise UsageError(f"--merge {args.merge}: folder {os.path.dirname(os.path.abspath(args.merge))} does not exist")
    params = {name: method_params(name, args) for name in names}
    results = analyze_corpus(clips, args.output, methods=names, params=params, load=_load_options(args),
                             scheduler=args.scheduler, workers=args.workers, merge=args.merge,
                             max_memory=max_memory, spill_dir=args.spill_dir, overwrite=args.overwrite,
                             progress=not args.quiet)
    failed = [r for r in results if r.status == FAILED]
    if not args.quiet:
        print(format_table(results))
        if args.merge is not None:
            print(f"merged {len(results) - len(failed)} textures into {args.merge}")
    if failed:
        print(f"dynatex: error: {len(failed)} of {len(results)} clips failed (first: "
              f"{os.path.basename(failed[0].clip)}: {failed[0].reason})", file=sys.stderr)
        return 2
    return 0


def _summary(name: str, model) -> str:
    info = getattr(model, "info", {}) or {}
    if name == "lds":
        return (f"n={model.n} k={model.k}, energy {info.get('energy_captured', 0):.3f}, "
                f"spectral radius {info.get('spectral_radius_raw', 0):.4f} -> {info.get('spectral_radius', 0):.4f} "
                f"({info.get('poles_clipped', 0)} poles clipped)")
    if name == "mixture":
        return (f"S={model.components} d={model.dim} D={model.global_dim}, AR({model.order}) by Schwarz, "
                f"reconstruction error {info.get('recon_error', 0):.3f} (single PCA of d: "
                f"{info.get('recon_error_pca_dim', 0):.3f})")
    if name == "tiles":
        if model.torus is not None:
            return (f"quilted torus {info.get('period_w')}x{info.get('period_h')} of {model.n_tiles} cells of "
                    f"{model.tile_size[1]}x{model.tile_size[0]} (blocks {info.get('quilt_block')}), loop "
                    f"{model.loop_length} frames from {model.class_loop_start.tolist()}, "
                    f"cut cost {info.get('quilt_seam_cost', 0):.4g}")
        kind = (f"Wang set of {info.get('edge_colours')} edge colours" if model.wang
                else f"ring construction, toroidal cut cost {model.class_toroid_cost.mean():.4g}")
        return (f"{model.n_tiles} tiles of {model.tile_size[1]}x{model.tile_size[0]}, loop {model.loop_length} "
                f"frames from {model.class_loop_start.tolist()}, classes {', '.join(model.class_names)}, "
                f"{kind}, ring seam cost "
                f"{model.seam_cost[model.seam_cost > 0].mean() if (model.seam_cost > 0).any() else 0:.4g}")
    if name == "quilt":
        w, h = model.size
        return (f"{w}x{h} canvas from {model.n_blocks} blocks of {model.block[1]}x{model.block[0]}, "
                f"rank-{info.get('rank')} SVD error {100 * info.get('rank_error', 0):.2f}% "
                f"(comparing {info.get('compare_width')} instead of {info.get('full_width')} values per pixel)")
    if name == "turnpoints":
        return (f"{info.get('n_turn_points', 0)} turn points {model.turn_points.tolist()[:12]}, "
                f"{info.get('n_transitions', 0)} transitions, exit frame {model.exit_frame}")
    return ""
