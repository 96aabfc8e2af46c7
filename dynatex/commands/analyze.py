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

from ..analyzer.methods import AUTO, METHODS, Method, get_method
from ..params import Param
from ..tiledb import DatabaseWriter
from ..tiledb.schema import texture_name_from_path
from . import COMMANDS
from ._common import (
    MAX_COUNT,
    Number,
    Numbers,
    UsageError,
    add_param,
    count,
    positive_int,
    size_arg,
    tqdm_progress,
)

#: frames each mode plays for ``--methods auto``'s ranking
AUTO_FRAMES = 200


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "analyze",
        help=COMMANDS["analyze"],
        description="Read a clip, run the chosen methods and write them into a tile "
        "database (other textures already in it are kept). Given several clips "
        "(or a glob, a folder of clips, a .txt list), write one database per clip "
        "into the folder -o, skipping clips whose database is already complete, "
        "and print a summary; the exit code is 2 when some clips failed.",
    )
    p.add_argument(
        "clip",
        nargs="+",
        help="video file, folder of images, or .npy array (T, H, W[, C]) uint8; several clips, "
        "globs, folders of clips or .txt files listing clips analyse a corpus",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="tile database to create or update (.h5); with several clips, the folder of their databases",
    )
    p.add_argument(
        "--name",
        help="texture name: any letters, up to 64 characters, no '/' (default: the clip's file "
        "name without extension; one clip only)",
    )
    p.add_argument(
        "--methods",
        default="lds",
        help=f"comma-separated methods to run: {', '.join(METHODS)}, or auto (one clip): the methods that can "
        "suit the clip, each played against it and ranked, the best marked as the texture's default mode "
        "(default: lds)",
    )
    p.add_argument(
        "--auto-frames",
        type=positive_int,
        default=None,
        help="with --methods auto: frames each mode plays for the ranking (default 200)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="start a new database instead of updating one; with several clips, analyse every clip "
        "again (even those whose database is complete) and start --merge afresh",
    )
    g = p.add_argument_group("corpus and scale")
    g.add_argument(
        "--scheduler",
        default="none",
        metavar="none|local|tcp://HOST:PORT",
        help="where clips run: none (in this process, default), local (a Dask LocalCluster on this "
        "machine) or the address of a running Dask scheduler; needs dynatex[dask]",
    )
    g.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="workers of --scheduler local (default: CPU cores, at most one per clip); BLAS threads "
        "are split between them",
    )
    g.add_argument(
        "--merge",
        default=None,
        metavar="OUT.h5",
        help="afterwards, gather every clip's texture into this database (atomically)",
    )
    g.add_argument(
        "--max-memory",
        default=None,
        metavar="SIZE",
        help="bound per clip, e.g. 2GB: the clip is spilled to disk and lds and mixture learn out of "
        "core; other methods need the frames to fit",
    )
    g.add_argument(
        "--spill-dir",
        default=None,
        metavar="DIR",
        help="folder of the clip copies --max-memory spills (default: the system's temporary folder)",
    )
    g = p.add_argument_group("clip input")
    g.add_argument("--start", type=count, default=0, help="first frame (default 0)")
    g.add_argument("--stop", type=positive_int, default=None, help="stop before this frame")
    g.add_argument("--step", type=positive_int, default=1, help="take every STEP-th frame")
    g.add_argument("--crop", type=_crop_arg, default=None, metavar="X,Y,W,H", help="keep this region")
    g.add_argument("--resize", type=size_arg, default=None, metavar="WxH", help="resize frames")
    g.add_argument("--grey", action="store_true", help="analyse in grey levels instead of colour")
    groups = _add_method_options(p)
    groups["turnpoints"].add_argument(
        "--tp-plot",
        default=None,
        metavar="PNG",
        help="write a plot of the symmetry curve, turn points and probabilities",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars or summary")
    return p


def _crop_arg(text: str) -> tuple[int, int, int, int]:
    x, y, w, h = Numbers(Number(int, 0, MAX_COUNT), 4, "X,Y,W,H")(text)
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"crop {text!r}: width and height must be at least 1")
    return x, y, w, h


def _add_method_options(p: argparse.ArgumentParser) -> dict[str, argparse._ArgumentGroup]:
    """One option group per method, one option per declared parameter (:mod:`dynatex.analyzer.methods`)."""
    groups = {}
    for method in METHODS.values():
        g = groups[method.name] = p.add_argument_group(method.name, method.summary)
        for param in method.params:
            add_param(g, param, dest=_dest(method, param), default=param.default)
    return groups


def _dest(method: Method, param: Param) -> str:
    return f"{method.name}.{param.name}"


def method_params(name: str, args: argparse.Namespace) -> dict:
    """Keyword arguments of method ``name``'s learn function, from the command line (every declared
    parameter that has an option; clip paths stay paths, :func:`~dynatex.analyzer.corpus.learn_into`
    decodes them)."""
    method = get_method(name)
    params = {}
    for param in method.params:
        if param.flag_name is not None:
            value = getattr(args, _dest(method, param))
            params[param.name] = param.default if value is None else value
    return params


def run(args: argparse.Namespace) -> int:
    from ..analyzer.corpus import find_clips
    from ..analyzer.stream import parse_bytes

    names = [m.strip() for m in args.methods.split(",") if m.strip()]
    if not names:
        raise UsageError("--methods names no method")
    auto = AUTO in names
    if auto and names != [AUTO]:
        raise UsageError("--methods auto chooses the methods itself: name no other method beside it")
    methods = [] if auto else [get_method(m) for m in names]
    if args.auto_frames is not None and not auto:
        raise UsageError("--auto-frames works with --methods auto only")
    max_memory = None if args.max_memory is None else _parse_bytes_arg(parse_bytes, args.max_memory)
    clips = find_clips(args.clip)
    corpus = (
        len(clips) > 1
        or len(args.clip) > 1
        or args.scheduler != "none"
        or args.merge is not None
        or os.path.isdir(args.output)
    )
    if corpus:
        if auto:
            raise UsageError("--methods auto works with one clip at a time, not a corpus")
        return _run_corpus(args, clips, names, max_memory)
    return _run_one(args, clips[0], methods, max_memory, auto=auto)


def _parse_bytes_arg(parse, text: str) -> int:
    try:
        return parse(text)
    except ValueError as exc:
        raise UsageError(f"--max-memory: {exc}") from None


def _load_options(args: argparse.Namespace) -> dict:
    return {
        "start": args.start,
        "stop": args.stop,
        "step": args.step,
        "crop": args.crop,
        "size": args.resize,
        "color": not args.grey,
    }


def _run_one(args: argparse.Namespace, clip_path: str, methods, max_memory: int | None, *, auto: bool = False) -> int:
    from ..analyzer.corpus import learn_into

    texture = args.name or texture_name_from_path(clip_path)
    show = not args.quiet
    t0 = time.perf_counter()

    def report(name: str, model, seconds: float) -> None:
        if name == "turnpoints" and args.tp_plot:
            from ..analyzer.turnpoints import plot_turnpoints

            plot_turnpoints(model, args.tp_plot, title=texture)
        if show:
            print(f"{name}: {model.summary()} ({seconds:.1f} s)", file=sys.stderr)
        warning = model.describe().get("warning")
        if warning:
            print(f"dynatex: warning: {texture}: {warning}", file=sys.stderr)

    if auto:
        if max_memory is not None:
            raise UsageError("--methods auto plays every method against the clip in memory: drop --max-memory")
        return _run_auto(args, clip_path, texture, report, show, t0)
    params = {m.name: method_params(m.name, args) for m in methods}
    # Open (and so validate) an existing database before the long work.
    with DatabaseWriter(args.output, overwrite=args.overwrite) as writer:
        source = learn_into(
            writer,
            texture,
            clip_path,
            [m.name for m in methods],
            params=params,
            load=_load_options(args),
            max_memory=max_memory,
            spill_dir=args.spill_dir,
            isolate=True,
            progress=lambda stage: tqdm_progress(stage, show),
            on_model=report,
        )
    if show:
        _wrote(args, texture, source, [m.name for m in methods], t0)
    return 0


def _wrote(args: argparse.Namespace, texture: str, s, methods: list[str], t0: float) -> None:
    print(
        f"wrote texture {texture!r} ({s.width}x{s.height}x{s.channels}, {s.n_frames} frames, methods "
        f"{', '.join(methods)}) to {args.output} in {time.perf_counter() - t0:.1f} s"
    )


def _run_auto(args: argparse.Namespace, clip_path: str, texture: str, report, show: bool, t0: float) -> int:
    """``--methods auto``: choose the methods that can suit the clip, learn each (one that fails is left
    out with its reason), play each against the clip, rank them, store the best as the default mode."""
    from ..analyzer.auto import MODE_OF, choose_methods, learn_chosen
    from ..analyzer.video import load_clip_path

    with DatabaseWriter(args.output, overwrite=args.overwrite) as writer:  # validates an existing one first
        clip = load_clip_path(clip_path, isolate=True, progress=tqdm_progress("decode", show), **_load_options(args))
        choices = choose_methods(clip.frames)
        if show:
            for c in choices:
                print(f"auto: {c.method}: {'yes' if c.chosen else 'no'}: {c.reason}", file=sys.stderr)
        chosen = [c.method for c in choices if c.chosen]
        learned, failed = learn_chosen(
            writer,
            texture,
            clip,
            chosen,
            params={m: method_params(m, args) for m in chosen},
            progress=lambda stage: tqdm_progress(stage, show),
            on_model=report,
        )
        for method, reason in failed.items():
            print(f"dynatex: warning: {texture}: auto: {method} left out: {reason}", file=sys.stderr)
    reasons = {MODE_OF[c.method]: c.reason for c in choices if c.method in learned}
    _rank_into(args, texture, clip.frames, [MODE_OF[m] for m in learned], reasons, show)
    if show:
        _wrote(args, texture, clip.source_info(), learned, t0)
    return 0


def _rank_into(args: argparse.Namespace, texture: str, source, modes: list[str], reasons: dict, show: bool) -> None:
    """Play each learned mode against the source, rank them, store the best as the default mode."""
    from ..analyzer.auto import rank

    ranking = rank(
        args.output,
        texture,
        source,
        modes,
        frames=args.auto_frames or AUTO_FRAMES,
        reasons=reasons,
        progress=tqdm_progress("rank", show),
    )
    if ranking[0]["score"] is None:
        raise UsageError(f"--methods auto: no mode of {texture!r} could play ({ranking[0]['why']})")
    with DatabaseWriter(args.output) as writer:
        writer.put_default_mode(texture, ranking[0]["mode"], ranking)
    if show:
        print(format_ranking(ranking), file=sys.stderr)


def format_ranking(ranking: list[dict]) -> str:
    """The ranking as lines ``1. mode  verdict  why``, the first marked as the default mode."""
    lines = []
    for e in ranking:
        mark = " (default mode)" if e["rank"] == 1 else ""
        lines.append(f"  {e['rank']}. {e['mode']:<10} {e['verdict']:<4}  {e['why']}{mark}")
        if e.get("reason"):
            lines.append(f"     chosen: {e['reason']}")
    return "\n".join(lines)


def _run_corpus(args: argparse.Namespace, clips: list[str], names: list[str], max_memory: int | None) -> int:
    from ..analyzer.corpus import FAILED, analyze_corpus, format_table

    for flag, value in (
        ("--name", args.name),
        ("--tiles-mix", getattr(args, "tiles.mix")),
        ("--tp-plot", args.tp_plot),
    ):
        if value:
            raise UsageError(f"{flag} works with one clip only, not a corpus of {len(clips)}")
    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise UsageError(
            f"-o {args.output}: with several clips -o names a folder for their databases, and this is a file"
        )
    if args.merge is not None and os.path.isdir(args.merge):
        raise UsageError(f"--merge {args.merge}: is a folder, not a database file")
    if args.merge is not None and not os.path.isdir(os.path.dirname(os.path.abspath(args.merge))):
        raise UsageError(f"--merge {args.merge}: folder {os.path.dirname(os.path.abspath(args.merge))} does not exist")
    params = {name: method_params(name, args) for name in names}
    results = analyze_corpus(
        clips,
        args.output,
        methods=names,
        params=params,
        load=_load_options(args),
        scheduler=args.scheduler,
        workers=args.workers,
        merge=args.merge,
        max_memory=max_memory,
        spill_dir=args.spill_dir,
        overwrite=args.overwrite,
        progress=not args.quiet,
    )
    failed = [r for r in results if r.status == FAILED]
    if not args.quiet:
        print(format_table(results))
        if args.merge is not None:
            print(f"merged {len(results) - len(failed)} textures into {args.merge}")
    if failed:
        print(
            f"dynatex: error: {len(failed)} of {len(results)} clips failed (first: "
            f"{os.path.basename(failed[0].clip)}: {failed[0].reason})",
            file=sys.stderr,
        )
        return 2
    return 0
