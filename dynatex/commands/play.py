"""``dynatex play DB.h5``: render frames of a texture to a video or PNG files."""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from ..player import open_player
from ..player.loop import loop_frames, wrap_report
from ..player.modes import player_class
from ..player.modes import ratemap as _ratemap
from . import COMMANDS
from ._common import Number, Numbers, UsageError, positive_int
from ._modes import add_mode_arguments, apply_controls, known_count, player_kwargs, resolve_args_mode
from ._output import H264_CRF, H264_PRESET, H264_PRESETS, MAX_FPS, MIN_FPS, FrameWriter

RATE = Number(float, 0.0, _ratemap.MAX_RATE)
FINITE = Number(float)
#: the parameters every mode shares that ``play`` offers (pixel format: the output file decides)
COMMON = ("backend", "device", "seed")
#: None: the texture's own mode (the analysis's choice, else the first method it holds in mode order)
DEFAULT_MODE = None
#: frames ``play`` renders when --frames is not given
DEFAULT_FRAMES = 250


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "play",
        help=COMMANDS["play"],
        description="Play a texture with the real-time player and write the frames to a "
        "video (.mp4: H.264, browser-playable; .mkv, .avi), an animated image "
        "(.webp, .apng, .gif; looping) or numbered PNG files (an output ending in "
        "'.png' or a folder).",
    )
    p.add_argument("database")
    p.add_argument("--texture", help="texture name (optional when the database holds one)")
    p.add_argument(
        "--frames",
        type=positive_int,
        default=None,
        help=f"frames to render, %(type)s (default {DEFAULT_FRAMES}; evolve holding its last frame: until the "
        "clock reaches the source's last frame at --speed, at most that)",
    )
    p.add_argument(
        "--loop",
        action="store_true",
        help="the last frame leads into the first as any other step does (export --loop's method per "
        "mode, at the source's pace: tiles and turnpoints play the whole number of tile loops or swings "
        "nearest --frames, other modes crossfade a quarter of the frames across the wrap); the wrap "
        "discontinuity is reported",
    )
    p.add_argument(
        "--fps",
        type=Number(float, MIN_FPS, MAX_FPS),
        default=None,
        help="frame rate of the video, in %(type)s (default: the source's)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="out.mp4 / .mkv / .avi / .webp / .apng / .gif, frame_%%04d.png, or a folder",
    )
    g = p.add_argument_group(".mp4 (H.264) encoding")
    g.add_argument(
        "--crf",
        type=Number(int, 0, 51),
        default=H264_CRF,
        help="constant rate factor, %(type)s: lower is better and larger (default %(default)s)",
    )
    g.add_argument(
        "--preset",
        choices=H264_PRESETS,
        default=H264_PRESET,
        help="x264 preset: slower makes smaller files at the same quality (default %(default)s)",
    )
    cls = add_mode_arguments(p, argv, default=DEFAULT_MODE, common=COMMON)
    mode = cls.mode
    if "rate_map" in cls.controls():
        g = p.add_argument_group(f"{mode} rate map")
        g.add_argument(
            "--rate-map",
            default=None,
            metavar="SPEC",
            help="per-pixel rate of evolution M: an image (grey, scaled to --rate-range) or .npy of "
            "rates the size of the output, halves:LEFT,RIGHT, or light:X,Y,HEIGHT[,MAX[,MIN]] "
            "(fall-off from a point light)",
        )
        g.add_argument(
            "--rate-range",
            type=Numbers(RATE, 2, "LOW,HIGH"),
            default=(0.0, 2.0),
            metavar="LOW,HIGH",
            help="rates of black and white in a --rate-map image: %(type)s (default 0,2)",
        )
    if cls.capabilities.inpaint:
        g = p.add_argument_group(f"{mode} inpainting")
        g.add_argument(
            "--inpaint",
            default=None,
            metavar="VIDEO",
            help="fill the --mask region of this video's frames with synthesized texture",
        )
        g.add_argument("--mask", default=None, metavar="MASK.png|.npy", help="inpainting mask, nonzero = fill")
    return p


def player_options(args: argparse.Namespace) -> dict:
    """Constructor options of the chosen mode, from the command line."""
    opts = known_count(player_class(args.mode), player_kwargs(args, player_class(args.mode), common=COMMON))
    if getattr(args, "inpaint", None):
        opts["size"] = _inpaint_size(args)
    elif getattr(args, "mask", None):
        raise UsageError("--mask needs --inpaint")
    return opts


def _apply(player, args: argparse.Namespace) -> None:
    apply_controls(player, args)
    if getattr(args, "rate_map", None) is not None:
        player.rate_map = rate_map_arg(args.rate_map, args.rate_range, player.shape[:2])


def rate_map_arg(spec: str, rate_range: tuple[float, float], shape: tuple[int, int]) -> np.ndarray:
    """The rate map ``--rate-map SPEC`` describes, for an output of ``shape`` (H, W)."""
    from ..player.modes import ratemap

    kind, _, rest = spec.partition(":")
    if kind in ("halves", "light") and rest:
        vals = [FINITE.check_part(f"--rate-map {kind}", v) for v in rest.split(",")]
        if kind == "halves":
            if len(vals) != 2:
                raise UsageError(f"--rate-map halves:LEFT,RIGHT needs two rates, not {rest!r}")
            return ratemap.halves(shape, *vals)
        if not 3 <= len(vals) <= 5:
            raise UsageError(f"--rate-map light:X,Y,HEIGHT[,MAX[,MIN]] needs 3 to 5 numbers, not {rest!r}")
        extra = dict(zip(("max_rate", "min_rate"), vals[3:]))
        return ratemap.point_light(shape, vals[:2], vals[2], **extra)
    if not os.path.isfile(spec):
        raise UsageError(f"--rate-map: no such file {spec!r} (or use halves:L,R or light:X,Y,H)")
    if spec.endswith(".npy"):
        return np.load(spec, allow_pickle=False)
    import cv2

    img = cv2.imread(spec, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise UsageError(f"--rate-map: cannot read image {spec!r}")
    low, high = rate_range
    return ratemap.from_image(img, low=low, high=high)


def _inpaint_size(args: argparse.Namespace) -> tuple[int, int]:
    """The (height, width) of the --inpaint video's frames (the player's output size)."""
    if not args.mask:
        raise UsageError("--inpaint needs --mask")
    import cv2

    cap = cv2.VideoCapture(args.inpaint)
    ok, first = cap.read()
    cap.release()
    if not ok:
        raise UsageError(f"--inpaint: cannot read a frame of {args.inpaint}")
    return first.shape[0], first.shape[1]


def default_frames(player) -> int:
    """:data:`DEFAULT_FRAMES`, or fewer for a player whose clock stops (``player.still_after``:
    an evolve player that holds the last source frame), rather than seconds of a still frame."""
    still = player.still_after
    return DEFAULT_FRAMES if still is None else min(DEFAULT_FRAMES, still)


def _run_inpaint(args: argparse.Namespace, player, writer: FrameWriter, fps: float | None) -> int:
    """Frames of the --inpaint video with the --mask region synthesized (mode tiles)."""
    import cv2

    if args.mask.endswith(".npy"):
        mask = np.load(args.mask, allow_pickle=False)
    else:
        mask = cv2.imread(args.mask, cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise UsageError(f"--mask: cannot read {args.mask}")
    cap = cv2.VideoCapture(args.inpaint)
    try:
        writer.open(player.shape, fps if fps is not None else cap.get(cv2.CAP_PROP_FPS) or 25.0, args.frames)
        out = np.empty(player.shape, np.uint8)
        n = 0
        with writer:
            while n < (args.frames or DEFAULT_FRAMES):
                ok, bgr = cap.read()
                if not ok:
                    break
                player.inpaint(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), mask, out=out)
                writer.write(out)
                n += 1
    finally:
        cap.release()
    print(
        f"inpainted {n} frames ({player.shape[1]}x{player.shape[0]}) of {args.inpaint} to {args.output}",
        file=sys.stderr,
    )
    return 0


def _run_loop(args: argparse.Namespace, writer: FrameWriter) -> int:
    """``--loop``: the frames of :func:`dynatex.player.loop.loop_frames`, and the wrap reported."""
    if player_class(args.mode).capabilities.native_loop and getattr(args, "speed", None) is not None:
        raise UsageError(f"--speed is set by --loop with mode {args.mode} (whole loops at the source's pace)")
    t0 = time.perf_counter()
    with open_player(args.database, args.texture, mode=args.mode, **player_options(args)) as player:
        _apply(player, args)
        fps = args.fps if args.fps is not None else player.texture.source.fps
        frames, how, _ = loop_frames(player, args.frames, keep_pace=True)
        source = player.texture.frames().read() if player.texture.has_frames else None
    if source is not None and source.shape[-1] == 1:
        source = np.repeat(source, 3, axis=-1)
    wrap = wrap_report(frames, source)
    writer.open(frames.shape[1:], fps, len(frames))
    with writer:
        for frame in frames:
            writer.write(frame)
    dt = time.perf_counter() - t0
    ratio = wrap["ratio"]
    print(
        f"wrote {len(frames)} frames ({frames.shape[2]}x{frames.shape[1]}) to {args.output} in {dt:.2f} s; "
        f"loop: {how}; wrap discontinuity {'n/a' if ratio is None else f'{ratio:.2f}'} x the {wrap['reference']}",
        file=sys.stderr,
    )
    return 0


def run(args: argparse.Namespace) -> int:
    resolve_args_mode(args)
    writer = FrameWriter(args.output, crf=args.crf, preset=args.preset, progress=True)
    if getattr(args, "inpaint", None) and args.loop:
        raise UsageError("--loop does not apply to --inpaint (the frames follow the inpainted video)")
    if getattr(args, "inpaint", None):
        with open_player(args.database, args.texture, mode=args.mode, **player_options(args)) as player:
            _apply(player, args)
            return _run_inpaint(args, player, writer, args.fps)
    if args.loop:
        return _run_loop(args, writer)
    with open_player(args.database, args.texture, mode=args.mode, **player_options(args)) as player:
        _apply(player, args)
        if args.frames is None:
            args.frames = default_frames(player)
        fps = args.fps if args.fps is not None else player.texture.source.fps
        writer.open(player.shape, fps, args.frames)
        t0 = time.perf_counter()
        frame = np.empty(player.shape, np.uint8)
        with writer:
            for _ in range(args.frames):
                player.next_frame(out=frame)
                writer.write(frame)
        dt = time.perf_counter() - t0
    print(
        f"wrote {args.frames} frames ({player.shape[1]}x{player.shape[0]}) to {args.output} in {dt:.2f} s",
        file=sys.stderr,
    )
    return 0
