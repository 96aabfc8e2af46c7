"""``dynatex play DB.h5``: render frames of a texture to a video or PNG files."""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from ..player import MODES, open_player
from ._common import UsageError, positive_int, size_arg


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("play", help="render frames of a texture to a video or PNG frames",
                       description="Play a texture with the real-time player and write the frames to an "
                                   "MP4/AVI video (OpenCV) or to numbered PNG files (an output ending in "
                                   "'.png' or a folder).")
    p.add_argument("database")
    p.add_argument("--texture", help="texture name (optional when the database holds one)")
    p.add_argument("--mode", default="lds", choices=sorted(MODES))
    p.add_argument("--frames", type=positive_int, default=250, help="frames to render (default 250)")
    p.add_argument("--size", type=size_arg, default=None, metavar="WxH",
                   help="output size, for modes that synthesize any size")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fps", type=float, default=None, help="frame rate of the video (default: the source's)")
    p.add_argument("--backend", choices=("auto", "opencl", "numpy"), default="auto",
                   help="auto (default): OpenCL on a device that passed the self-test, else numpy")
    p.add_argument("--device", default=None, help="OpenCL device (index P:D, or a name substring)")
    p.add_argument("-o", "--output", required=True, help="out.mp4 / out.avi, frame_%%04d.png, or a folder")
    g = p.add_argument_group("lds controls")
    g.add_argument("--speed", type=float, default=1.0, help="in [-3, 3]; negative plays backwards")
    g.add_argument("--intensity", type=float, default=1.0, help=">= 0, scale of the driving noise")
    g.add_argument("--scales", default=None, metavar="C,M,F", help="coarse,medium,fine weights in [0, 10]")
    g.add_argument("--precision", choices=("float32", "float16"), default="float32")
    g = p.add_argument_group("mixture controls (also --intensity, --precision)")
    g.add_argument("--draws", type=positive_int, default=16,
                   help="noise draws per step, the one nearest the learned manifold is kept (default 16)")
    g = p.add_argument_group("turnpoints controls (--speed in [0, 4])")
    g.add_argument("--playback", choices=("hybrid", "turns", "jumps"), default="hybrid",
                   help="turn points and transitions (default), turn points only, transitions only")
    g.add_argument("--crossfade", type=int, default=4, help="frames of crossfade at a jump, 0..16 (default 4)")
    g.add_argument("--increment", type=float, default=0.1, help="step of the adaptive reversal probabilities")
    g.add_argument("--start", type=int, default=0, help="first source frame (default 0)")
    g = p.add_argument_group("tiles controls (also --size, --speed in [-4, 4])")
    g.add_argument("--sigma", type=float, default=None,
                   help="Gaussian smoothing of the per-tile time offsets, output pixels (default half a tile)")
    g.add_argument("--max-shift", type=float, default=None, help="amplitude of the time offsets, frames "
                   "(default a third of the loop, at most 16)")
    g.add_argument("--epoch", type=int, default=None,
                   help="frames over which the offsets drift to a new field, 0 = fixed (default 2 loops)")
    g.add_argument("--tone", default=None, metavar="TEXTURE|consensus|R,G,B",
                   help="fit tile colours to a texture class's tone, the consensus of all, or a colour")
    g.add_argument("--labels", default=None, metavar="PRESET|FILE.npy",
                   help="which texture class goes where: halves, stripes, checker, blobs, or an .npy map "
                        "(tile cells or pixels) of class indices")
    g.add_argument("--inpaint", default=None, metavar="VIDEO",
                   help="fill the --mask region of this video's frames with synthesized texture")
    g.add_argument("--mask", default=None, metavar="MASK.png|.npy", help="inpainting mask, nonzero = fill")
    g = p.add_argument_group("evolve controls (time-varying textures; also --speed in [-16, 16], --size must "
                             "match the analysed quilt)")
    g.add_argument("--jitter", type=float, default=0.0, metavar="E",
                   help="per-block time jitter: monotone, at most E frames from the true time (default 0)")
    g.add_argument("--end", choices=("hold", "loop", "pingpong"), default="hold",
                   help="after the last source frame: hold it, loop to the first, or play back and forth")
    g.add_argument("--rate-map", default=None, metavar="SPEC",
                   help="per-pixel rate of evolution M: an image (grey, scaled to --rate-range) or .npy of rates "
                        "the size of the output, halves:LEFT,RIGHT, or light:X,Y,HEIGHT[,MAX[,MIN]] "
                        "(fall-off from a point light)")
    g.add_argument("--rate-range", default="0,2", metavar="LOW,HIGH",
                   help="rates of black and white in a --rate-map image (default 0,2)")
    g.add_argument("--rate-sigma", type=float, default=0.0, help="Gaussian smoothing of the rate map, pixels")
    g.add_argument("--no-interpolate", action="store_true", help="nearest earlier frame instead of blending")
    return p


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
            try:
                player.scales = [float(v) for v in args.scales.split(",")]
            except ValueError:
                raise UsageError(f"--scales must be three numbers C,M,F, not {args.scales!r}") from None


def rate_map_arg(spec: str, rate_range: str, shape: tuple[int, int]) -> np.ndarray:
    """The rate map ``--rate-map SPEC`` describes, for an output of ``shape`` (H, W)."""
    from ..player import ratemap
    kind, _, rest = spec.partition(":")
    if kind in ("halves", "light") and rest:
        try:
            vals = [float(v) for v in rest.split(",")]
        except ValueError:
            raise UsageError(f"--rate-map {kind}: expected numbers after '{kind}:', not {rest!r}") from None
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
    try:
        low, high = (float(v) for v in rate_range.split(","))
    except ValueError:
        raise UsageError(f"--rate-range must be LOW,HIGH, not {rate_range!r}") from None
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
        tone = args.tone
        if "," in tone:
            try:
                tone = tuple(float(v) for v in tone.split(","))
            except ValueError:
                raise UsageError(f"--tone colour must be R,G,B numbers, not {args.tone!r}") from None
        opts["tone"] = tone
    return opts


def _run_inpaint(args: argparse.Namespace, player, writer: "FrameWriter", fps: float | None) -> int:
    """Frames of the --inpaint video with the --mask region synthesized (mode tiles)."""
    import cv2
    if args.mask.endswith(".npy"):
        mask = np.load(args.mask, allow_pickle=False)
    else:
        mask = cv2.imread(args.mask, cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise UsageError(f"--mask: cannot read {args.mask}")
    cap = cv2.VideoCapture(args.inpaint)
    fps = fps or cap.get(cv2.CAP_PROP_FPS) or 25.0
    out = np.empty(player.shape, np.uint8)
    n = 0
    try:
        while n < args.frames:
            ok, bgr = cap.read()
            if not ok:
                break
            player.inpaint(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), mask, out=out)
            writer.write(out, fps)
            n += 1
    finally:
        cap.release()
        writer.close()
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
        fps = args.fps or player.texture.source.fps
        t0 = time.perf_counter()
        frame = np.empty(player.shape, np.uint8)
        try:
            for _ in range(args.frames):
                player.next_frame(out=frame)
                writer.write(frame, fps)
        finally:
            writer.close()
        dt = time.perf_counter() - t0
    print(f"wrote {args.frames} frames ({player.shape[1]}x{player.shape[0]}) to {args.output} "
          f"in {dt:.2f} s", file=sys.stderr)
    return 0


class FrameWriter:
    """Writes RGB frames to a video (OpenCV VideoWriter) or numbered PNGs."""

    def __init__(self, output: str) -> None:
        self.output = output
        self.index = 0
        self._video = None
        low = output.lower()
        if low.endswith(".png"):
            self.kind = "png"
            self.pattern = output if "%" in output else output[:-4] + "_%05d.png"
        elif os.path.isdir(output) or output.endswith(os.sep):
            os.makedirs(output, exist_ok=True)
            self.kind = "png"
            self.pattern = os.path.join(output, "frame_%05d.png")
        elif low.endswith((".mp4", ".avi", ".mkv")):
            self.kind = "video"
        else:
            raise UsageError(f"output {output!r}: use .mp4, .avi, .mkv, a .png pattern or a folder")
        folder = os.path.dirname(os.path.abspath(self.pattern if self.kind == "png" else output))
        if not os.path.isdir(folder):
            raise UsageError(f"output folder {folder} does not exist")

    def write(self, frame: np.ndarray, fps: float) -> None:
        import cv2
        bgr = cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)
        if self.kind == "png":
            path = self.pattern % self.index
            if not cv2.imwrite(path, bgr):
                raise OSError(f"cannot write {path}")
        else:
            if self._video is None:
                fourcc = {".mp4": "mp4v", ".avi": "MJPG", ".mkv": "XVID"}[os.path.splitext(self.output)[1].lower()]
                self._video = cv2.VideoWriter(self.output, cv2.VideoWriter_fourcc(*fourcc), float(fps),
                                              (frame.shape[1], frame.shape[0]))
                if not self._video.isOpened():
                    raise OSError(f"OpenCV cannot write video {self.output}")
            self._video.write(bgr)
        self.index += 1

    def close(self) -> None:
        if self._video is not None:
            self._video.release()
            self._video = None
