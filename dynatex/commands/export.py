"""``dynatex export DB.h5 -o FOLDER``: a flipbook bundle for game engines from any mode.

Writes ``NAME_COLSxROWS.png`` (colour atlas, sRGB), ``NAME_COLSxROWS_mv.png`` (motion vectors,
linear) and ``NAME.json`` (the values engines need; see :mod:`dynatex.analyzer.flipbook`), or
with ``--layout array`` one raw layer per frame. ``--loop`` makes the frames a closed loop:

- tiles: the tile loop itself (fixed time offsets), ``--frames`` steps around it;
- turnpoints: the longest swing between two consecutive turn points and back, a path that
  returns to its start (``--frames`` resamples it, blending neighbouring source frames);
- lds, mixture, evolve: ``FRAMES + BLEND`` frames are rendered and the last ``BLEND`` are
  crossfaded into the first ``BLEND``, so the frame after the last is the sequence's own
  next frame.

The wrap (last frame -> first) is measured against the source's median frame step
(:func:`dynatex.player.loop.wrap_report`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from ..player import MODES, open_player
from ..player.loop import loop_frames, wrap_report
from ..player.loop import render as render_frames
from ..player.modes import player_class
from . import COMMANDS
from ._common import Number, UsageError, size_arg
from ._modes import add_mode_arguments, apply_controls, known_count, player_kwargs, resolve_args_mode
from ._output import MAX_FPS, MIN_FPS, OutputError

#: Most frames a flipbook holds (a 64x64 grid).
MAX_FRAMES = 4096
#: Frames rendered when neither --frames nor a mode's own loop says how many.
DEFAULT_FRAMES = 64
#: None: the texture's own mode (the analysis's choice, else the first method it holds in mode order)
DEFAULT_MODE = None
#: the ``--packing`` rules (:func:`dynatex.analyzer.flipbook.choose_grid`)
PACKINGS = ("packed", "pow2", "square")
#: the parameters every mode shares that ``export`` offers (the atlas is RGB(A) by its own rule)
COMMON = ("backend", "device", "seed")


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "export",
        help=COMMANDS["export"],
        description="Render frames of a texture and write a flipbook for Unity, Unreal or Godot: "
        "NAME_COLSxROWS.png (colour atlas, sRGB, frames row-major from the top-left, packed by --packing), "
        "NAME_COLSxROWS_mv.png (optical-flow motion vectors, RG centred at 128, linear) "
        "and NAME.json (grid, frame count, fps, motion-vector scale for Unity VFX Graph "
        "and Unreal, the loop's wrap discontinuity).",
    )
    p.add_argument("database")
    p.add_argument("-o", "--output", required=True, metavar="FOLDER", help="folder for the bundle (created)")
    p.add_argument("--texture", help="texture name (optional when the database holds one)")
    p.add_argument("--name", default=None, help="file name stem (default: the texture's name)")
    p.add_argument(
        "--frames",
        type=Number(int, 1, MAX_FRAMES),
        default=None,
        help=f"frames in the flipbook, %(type)s (default {DEFAULT_FRAMES}, or with --loop the mode's "
        "own loop: tiles' loop length, turnpoints' swing)",
    )
    p.add_argument("--loop", action="store_true", help="a seamless closed loop (method per mode: see the README)")
    p.add_argument(
        "--blend",
        type=Number(int, 1, MAX_FRAMES),
        default=None,
        help="lds/mixture/evolve --loop: frames crossfaded across the wrap, %(type)s (default a quarter of the frames)",
    )
    p.add_argument(
        "--fps",
        type=Number(float, MIN_FPS, MAX_FPS),
        default=None,
        help="frame rate written to the sidecar, in %(type)s (default: the source's; a tiles or "
        "turnpoints loop resampled to --frames keeps the source's pace)",
    )
    p.add_argument(
        "--packing",
        choices=PACKINGS,
        default="packed",
        help="packed (default): no empty cell where the frame count allows (else the fewest), an atlas at most "
        "2:1, cells of the frame's own aspect and size (any grid: Unity VFX Graph and particle sheets, Unreal "
        "SubUV, Godot); pow2: a power-of-two atlas, each cell side the power of two nearest the frame's "
        "(engines that need power-of-two textures); square: the near-square grid of frame-sized cells",
    )
    p.add_argument("--npot", action="store_const", dest="packing", const="square", help="the same as --packing square")
    p.add_argument(
        "--grid",
        type=size_arg,
        default=None,
        metavar="COLSxROWS",
        help="grid (default: by --packing)",
    )
    p.add_argument(
        "--tile",
        type=size_arg,
        default=None,
        metavar="WxH",
        help="size of one frame in the atlas (default: the frame's, or with --packing pow2 each side the power "
        "of two nearest the frame's)",
    )
    p.add_argument("--no-motion-vectors", action="store_true", help="write the colour atlas only")
    p.add_argument(
        "--layout",
        dest="file_layout",  # a player option of mode tiles is named layout
        choices=("atlas", "array"),
        default="atlas",
        help="atlas (default), or array: NAME_array_rgba8.raw, one RGBA8 layer per frame "
        "(and NAME_array_rg8.raw), described in NAME.json",
    )
    p.add_argument(
        "--source",
        default=None,
        metavar="CLIP",
        help="the clip the texture was analysed from, the reference of the wrap discontinuity "
        "(default: the frames the database stores, else the export's own frame step)",
    )
    add_mode_arguments(p, argv, default=DEFAULT_MODE, common=COMMON)
    return p


# -- frames ------------------------------------------------------------------------------------------
def render(args: argparse.Namespace) -> tuple[np.ndarray, str, float, np.ndarray | None]:
    """The flipbook's frames ``(N, H, W, 3)``, a description of the loop, the frame rate and the
    source frames (None when the database stores none)."""
    cls = player_class(resolve_args_mode(args))
    if args.blend is not None and not (args.loop and not cls.capabilities.native_loop):
        blended = sorted(m for m in MODES if not player_class(m).capabilities.native_loop)
        raise UsageError(f"--blend belongs to --loop with mode {', '.join(blended)}")
    if args.loop and getattr(args, "speed", None) is not None:
        raise UsageError("--speed is set by --loop (the loop's length and --frames)")
    opts = known_count(cls, player_kwargs(args, cls, common=COMMON))
    with open_player(args.database, args.texture, mode=args.mode, **opts) as player:
        fps = args.fps if args.fps is not None else player.texture.source.fps
        source = player.texture.frames().read() if player.texture.has_frames else None
        if source is not None and source.shape[-1] == 1:
            source = np.repeat(source, 3, axis=-1)
        apply_controls(player, args)
        args.texture_name = player.texture.name
        if not args.loop:
            return render_frames(player, args.frames or DEFAULT_FRAMES), "none", fps, source
        n = args.frames if args.frames is not None or cls.capabilities.native_loop else DEFAULT_FRAMES
        if args.blend is not None and args.blend >= n:
            raise UsageError(f"--blend {args.blend} must be fewer than the {n} frames")
        frames, how, pace = loop_frames(player, n, blend=args.blend)
        if args.fps is None:
            fps /= pace
        return frames, how, fps, source


# -- the bundle ---------------------------------------------------------------------------------------
def _write_png(path: str, image: np.ndarray) -> None:
    import cv2

    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OutputError(f"cannot encode {path}")
    _write_bytes(path, data.tobytes())


def _write_bytes(path: str, data: bytes) -> None:
    try:
        with open(path, "wb") as f:
            f.write(data)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None


def run(args: argparse.Namespace) -> int:
    from ..analyzer import flipbook as fb

    out = args.output
    if os.path.exists(out) and not os.path.isdir(out):
        raise OutputError(f"output {out} exists and is not a folder")
    frames, how, fps, source = render(args)
    if args.source is not None:
        from ._common import load_clip_arg

        source = load_clip_arg(args.source).frames
    name = args.name if args.name is not None else args.texture_name
    if not name or "/" in name or name in (".", ".."):
        raise UsageError(f"--name {name!r}: a file name stem without '/' is needed")
    rows, cols = args.grid if args.grid is not None else (None, None)  # COLSxROWS, parsed like WxH
    tile = args.tile
    try:
        grid = fb.choose_grid(
            len(frames),
            frames.shape[1:3],
            cols=cols,
            rows=rows,
            tile=tile,
            pow2=args.packing == "pow2",
            packed=args.packing == "packed",
        )
    except ValueError as exc:
        raise UsageError(f"--grid/--tile: {exc}") from None
    tiles = np.stack([fb.fit(f, grid.tile) for f in frames])
    wrap = wrap_report(frames, source)
    strength = uv = None
    if not args.no_motion_vectors:
        uv = fb.flow_to_uv(fb.frame_motion(fb.optical_flow(tiles, wrap=args.loop), wrap=args.loop))
        _, strength = fb.encode_vectors(uv)
    src = {
        "texture": name,
        "mode": args.mode,
        "width": int(frames.shape[2]),
        "height": int(frames.shape[1]),
        "seed": getattr(args, "seed", 0),
    }
    packed = fb.packing(grid, frames.shape[1:3], args.packing)
    doc = fb.sidecar(
        name, grid, fps=fps, loop=how, strength=strength, source=src, wrap=wrap, layout=args.file_layout, packed=packed
    )
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output folder {out}: {exc.strerror or exc}") from None
    files = doc["files"]
    if args.file_layout == "atlas":
        _write_png(os.path.join(out, files["color"]), fb.color_atlas(tiles, grid))
        if uv is not None:
            _write_png(os.path.join(out, files["motion_vectors"]), fb.vector_atlas(uv, grid, strength)[0])
    else:
        rgba = np.concatenate([tiles, np.full(tiles.shape[:3] + (1,), 255, np.uint8)], -1)
        _write_bytes(os.path.join(out, files["color"]), rgba.tobytes())
        if uv is not None:
            _write_bytes(os.path.join(out, files["motion_vectors"]), fb.encode_vectors(uv, strength)[0].tobytes())
    _write_bytes(os.path.join(out, f"{name}.json"), (json.dumps(doc, indent=2, ensure_ascii=False) + "\n").encode())
    ratio = wrap.get("ratio")
    print(
        f"wrote {grid.frames} frames ({grid.cols}x{grid.rows} grid of {grid.tile[1]}x{grid.tile[0]}, "
        f"{packed['empty_cells']} empty cells, cell aspect {packed['cell_aspect']:g} for frames of "
        f"{packed['frame_aspect']:g}) to {out}: "
        f"{', '.join(files.values())}, {name}.json; loop: {how}; wrap discontinuity "
        f"{'n/a' if ratio is None else f'{ratio:.2f}'} x the "
        f"{wrap['reference']}",
        file=sys.stderr,
    )
    return 0
