"""``dynatex play DB.h5``: render frames of a texture to a video or PNG files."""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from ..player import MODES, open_player
from ..player import lds as _lds
from ..player import mixture as _mixture
from ..player import projected as _projected
from ..player import quilt as _quilt
from ..player import ratemap as _ratemap
from ..player import tiles as _tiles
from ..player import turnpoints as _turnpoints
from ..player.gather import MAX_TIME
from ._common import (
    MAX_COUNT,
    Number,
    Numbers,
    UsageError,
    count,
    positive_int,
    seed,
    size_arg,
)
from ._output import MAX_FPS, MIN_FPS, FrameWriter

#: --speed takes the widest range of any mode; the chosen mode narrows it when the player opens.
SPEED = Number(float, min(m.SPEED_RANGE[0] for m in (_lds, _tiles, _turnpoints, _quilt)),
               max(m.SPEED_RANGE[1] for m in (_lds, _tiles, _turnpoints, _quilt)))
RATE = Number(float, 0.0, _ratemap.MAX_RATE)
FINITE = Number(float)


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("play", help="render frames of a texture to a video or PNG frames",
                       description="Play a texture with the real-time player and write the frames to a "
                                   "video (.mp4: H.264, browser-playable; .mkv, .avi), an animated image "
                                   "(.webp, .apng, .gif; looping) or numbered PNG files (an output ending in "
                                   "'.png' or a folder).")
    p.add_argument("database")
    p.add_argument("--texture", help="texture name (optional when the database holds one)")
    p.add_argument("--mode", default="lds", choices=sorted(MODES))
    p.add_argument("--frames", type=positive_int, default=250, help="frames to render, %(type)s (default 250)")
    p.add_argument("--size", type=size_arg, default=None, metavar="WxH",
                   help="output size, for modes that synthesize any size")
    p.add_argument("--seed", type=seed, default=0, help="random seed, %(type)s (default 0)")
    p.add_argument("--fps", type=Number(float, MIN_FPS, MAX_FPS), default=None,
                   help="frame rate of the video, in %(type)s (default: the source's)")
    p.add_argument("--backend", choices=("auto", "opencl", "numpy"), default="auto",
                   help="auto (default): OpenCL on a device that passed the self-test, else numpy")
    p.add_argument("--device", default=None, help="OpenCL device (index P:D, or a name substring)")
    p.add_argument("-o", "--output", required=True, help="out.mp4 / .mkv / .avi / .webp / .apng / .gif, frame_%%04d.png, or a folder")
    g = p.add_argument_group("lds controls")
    g.add_argument("--speed", type=SPEED, default=1.0, help="in [-3, 3]; negative plays backwards")
    g.add_argument("--intensity", type=Number(float, 0.0, _projected.MAX_INTENSITY), default=1.0,
                   help="scale of the driving noise, in %(type)s (default 1)")
    g.add_argument("--scales", type=Numbers(Number(float, 0.0, _lds.MAX_WEIGHT), 3, "C,M,F"), default=None,
                   metavar="C,M,F", help="coarse,medium,fine weights: %(type)s")
    g.add_argument("--precision", choices=("float32", "float16"), default="float32")
    g = p.add_argument_group("mixture controls (also --intensity, --precision)")
    g.add_argument("--draws", type=Number(int, 1, _mixture.MAX_DRAWS), default=16,
                   help="noise draws per step, %(type)s; the one nearest the learned manifold is kept (default 16)")
    g = p.add_argument_group("turnpoints controls (--speed in [0, 4])")
    g.add_argument("--playback", choices=("hybrid", "turns", "jumps"), default="hybrid",
                   help="turn points and transitions (default), turn points only, transitions only")
    g.add_argument("--crossfade", type=Number(int, 0, _turnpoints.MAX_CROSSFADE), default=4,
                   help="frames of crossfade at a jump, %(type)s (default 4)")
    g.add_argument("--increment", type=Number(float, 0.0, 1.0), default=0.1,
                   help="step of the adaptive reversal probabilities, in %(type)s (default 0.1)")
    g.add_argument("--start", type=count, default=0, help="first source frame (default 0)")
    g = p.add_argument_group("tiles controls (also --size, --speed in [-4, 4])")
    g.add_argument("--sigma", type=Number(float, 0.0, 4096.0), default=None,
                   help="Gaussian smoothing of the per-tile time offsets, output pixels in %(type)s "
                        "(default half a tile)")
    g.add_argument("--max-shift", type=Number(float, 0.0, MAX_TIME), default=None,
                   help="amplitude of the time offsets, frames in %(type)s, at most the loop "
                        "(default a third of the loop, at most 16)")
    g.add_argument("--epoch", type=count, default=None,
                   help="frames over which the offsets drift to a new field, 0 = fixed (default 2 loops)")
    g.add_argument("--tone", type=_tone_arg, default=None, metavar="TEXTURE|consensus|R,G,B",
                   help="fit tile colours to a texture class's tone, the consensus of all, or a colour")
    g.add_argument("--labels", default=None, metavar="PRESET|FILE.npy",
                   help="which texture class goes where: halves, stripes, checker, blobs, or an .npy map "
                        "(tile cells or pixels) of class indices")
    g.add_argument("--inpaint", default=None, metavar="VIDEO",
                   help="fill the --mask region of this video's frames with synthesized texture")
    g.add_argument("--mask", default=None, metavar="MASK.png|.npy", help="inpainting mask, nonzero = fill")
    g = p.add_argument_group("evolve controls (time-varying textures; also --speed in [-16, 16], --size must "
                             "match the analysed quilt)")
    g.add_argument("--jitter", type=Number(float, 0.0, float(MAX_COUNT)), default=0.0, metavar="E",
                   help="per-block time jitter: monotone, at most E frames from the true time, E at most the "
                        "clip's frames (default 0)")
    g.add_argument("--end", choices=("hold", "loop", "pingpong"), default="hold",
                   help="after the last source frame: hold it, loop to the first, or play back and forth")
    g.add_argument("--rate-map", default=None, metavar="SPEC",
                   help="per-pixel rate of evolution M: an image (grey, scaled to --rate-range) or .npy of rates "
                        "the size of the output, halves:LEFT,RIGHT, or light:X,Y,HEIGHT[,MAX[,MIN]] "
                        "(fall-off from a point light)")
    g.add_argument("--rate-range", type=Numbers(RATE, 2, "LOW,HIGH"), default=(0.0, 2.0), metavar="LOW,HIGH",
                   help="rates of black and white in a --rate-map image: %(type)s (default 0,2)")
    g.add_argument("--rate-sigma", type=Number(float, 0.0, _quilt.MAX_SIGMA), default=0.0,
                   help="Gaussian smoothing of the rate map, pixels in %(type)s (default 0)")
    g.add_argument("--no-interpolate", action="store_true", help="nearest earlier frame instead of blending")
    return p


def _tone_arg(text: str) -> str | tuple[float, ...]:
    return Numbers(Number(float, 0.0, 255.0), 3, "R,G,B")(text) if "," in text else text


def player_options(args: argparse.Namespace) -> dict:
    """Constructor options of the chosen mode, from the command line."""
    opts = {"backend": args.backend, "device": args.device, "seed": args.seed}
    if args.mode == "lds":
        opts["precision"] = args.precision
    if args.mode == "mixture":
        opts["precision"] = args.precision
        opts["draws"] = args.draws
        if args.size is not None:
            raise UsageError("--size is not supported by mode mixture (it plays at the clip's resolution)")
    if args.mode == "turnpoints":
        opts["playback"] = args.playback
        opts["start"] = args.start
    if args.mode == "evolve":
        opts.update(size=args.size, jitter=args.jitter, end=args.end, rate_sigma=args.rate_sigma,
                    interpolate=not args.no_interpolate)
    elif args.rate_map is not None:
        raise UsageError("--rate-map belongs to mode evolve")
    if args.mode == "tiles":
        opts.update(_tiles_options(args))
    elif args.inpaint or args.labels or args.tone:
        raise UsageError("--inpaint, --labels and --tone belong to mode tiles")
    if args.size is not None and args.mode == "lds":
        raise UsageError("--size is not supported by mode lds (it plays at the clip's resolution)")
    if args.size is not None and args.mode == "turnpoints":
        raise UsageError("--size is not supported by mode turnpoints (it plays the source frames themselves)")
    return opts


def apply_controls(player, args: argparse.Namespace) -> None:
    if args.mode == "mixture":
        player.intensity = args.intensity
    if args.mode == "turnpoints":
        player.speed = args.speed
        player.crossfade = args.crossfade
        player.increment = args.increment
    if args.mode == "tiles":
        player.speed = args.speed
        for name in ("sigma", "max_shift", "epoch"):
            if getattr(args, name) is not None:
                setattr(player, name, getattr(args, name))
    if args.mode == "evolve":
        player.speed = args.speed
        if args.rate_map is not None:
            player.rate_map = rate_map_arg(args.rate_map, args.rate_range, player.shape[:2])
    if args.mode == "lds":
        player.speed = args.speed
        player.intensity = args.intensity
        if args.scales is not None:
            player.scales = list(args.scales)


def rate_map_arg(spec: str, rate_range: tuple[float, float], shape: tuple[int, int]) -> np.ndarray:
    """The rate map ``--rate-map SPEC`` describes, for an output of ``shape`` (H, W)."""
    from ..player import ratemap
    kind, _, rest = spec.partition(":")
    if kind in ("halves", "light") and rest:
        vals = [FINITE.check(f"--rate-map {kind}", v) for v in rest.split(",")]
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


def _tiles_options(args: argparse.Namespace) -> dict:
    opts: dict = {}
    if args.inpaint:
        if not args.mask:
            raise UsageError("--inpaint needs --mask")
        import cv2
        cap = cv2.VideoCapture(args.inpaint)
        ok, first = cap.read()
        cap.release()
        if not ok:
            raise UsageError(f"--inpaint: cannot read a frame of {args.inpaint}")
        opts["size"] = (first.shape[1], first.shape[0])
    elif args.mask:
        raise UsageError("--mask needs --inpaint")
    elif args.size is not None:
        opts["size"] = args.size
    if args.labels:
        if args.labels.endswith(".npy"):
            if not os.path.isfile(args.labels):
                raise UsageError(f"--labels: no such file {args.labels}")
            opts["labels"] = np.load(args.labels, allow_pickle=False)
        else:
            opts["labels"] = args.labels
    if args.tone:
        opts["tone"] = args.tone
    return opts


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
        writer.open(player.shape, fps if fps is not None else cap.get(cv2.CAP_PROP_FPS) or 25.0)
        out = np.empty(player.shape, np.uint8)
        n = 0
        with writer:
            while n < args.frames:
                ok, bgr = cap.read()
                if not ok:
                    break
                player.inpaint(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), mask, out=out)
                writer.write(out)
                n += 1
    finally:
        cap.release()
    print(f"inpainted {n} frames ({player.shape[1]}x{player.shape[0]}) of {args.inpaint} to {args.output}",
          file=sys.stderr)
    return 0


def run(args: argparse.Namespace) -> int:
    writer = FrameWriter(args.output)
    if getattr(args, "inpaint", None) and args.mode == "tiles":
        with open_player(args.database, args.texture, mode=args.mode, **player_options(args)) as player:
            apply_controls(player, args)
            return _run_inpaint(args, player, writer, args.fps)
    with open_player(args.database, args.texture, mode=args.mode, **player_options(args)) as player:
        apply_controls(player, args)
        fps = args.fps if args.fps is not None else player.texture.source.fps
        writer.open(player.shape, fps)
        t0 = time.perf_counter()
        frame = np.empty(player.shape, np.uint8)
        with writer:
            for _ in range(args.frames):
                player.next_frame(out=frame)
                writer.write(frame)
        dt = time.perf_counter() - t0
    print(f"wrote {args.frames} frames ({player.shape[1]}x{player.shape[0]}) to {args.output} "
          f"in {dt:.2f} s", file=sys.stderr)
    return 0
