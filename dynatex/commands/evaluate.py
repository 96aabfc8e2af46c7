"""``dynatex evaluate SOURCE OUTPUT``: quality metrics of a synthesized texture against its source."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from typing import Any

import numpy as np

from ..player import MODES
from . import COMMANDS
from ._common import UsageError, load_clip_arg, positive_int, seed, size_arg
from ._modes import known_count

DB_SUFFIXES = (".h5", ".hdf5")
#: exit code of ``--strict`` when a figure is out of its good range (usage and input errors are 2)
STRICT_EXIT = 3


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "evaluate",
        help=COMMANDS["evaluate"],
        description="Compare OUTPUT with SOURCE: long-run stability, seam visibility, temporal "
        "discontinuity at events, spectrum and patch likeness, mixed positions (local novelty), "
        "coverage and repetition "
        "(see analyzer/METRICS.md). OUTPUT is a video, a folder of images or a .npy array, "
        "or a tile database (.h5) played with --texture/--mode/--frames/--seed/--size.",
    )
    p.add_argument("source", help="source clip: video file, folder of images, or .npy (T, H, W[, C]) uint8")
    p.add_argument("output", help="synthesized clip (video, folder, .npy) or a tile database (.h5)")
    p.add_argument(
        "--boundaries",
        default=None,
        metavar="SPEC",
        help="seams to measure: grid:WxH[+X+Y] (a tile grid of W x H pixels, shifted by X,Y), "
        "border (the wrap-around border of a tileable texture), or an image whose distinct "
        "colours label regions (a seam lies wherever neighbouring labels differ)",
    )
    p.add_argument("--wrap", action="store_true", help="also count the wrap-around border as a seam")
    p.add_argument(
        "--events",
        default=None,
        metavar="LIST",
        help="frames that follow a jump (loop wrap, reversal): comma-separated indices, "
        "or every:N for every N-th frame",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument(
        "--strict",
        action="store_true",
        help=f"exit with code {STRICT_EXIT} when a figure is outside its good range (a verdict other than good)",
    )
    p.add_argument(
        "--sheet",
        default=None,
        metavar="PNG",
        help="also write a contact sheet: source frames beside output frames, to look at",
    )
    g = p.add_argument_group("database output (the player)")
    g.add_argument("--texture", help="texture name (optional when the database holds one)")
    g.add_argument("--mode", default="lds", choices=sorted(MODES), help="player mode (default lds)")
    g.add_argument(
        "--frames",
        type=positive_int,
        default=None,
        help="frames to play from a database (default 300), or to read from a video",
    )
    g.add_argument("--seed", type=seed, default=0, help="player seed, also the patch-sampling seed, %(type)s")
    g.add_argument(
        "--size", type=size_arg, default=None, metavar="WxH", help="output size, for modes that synthesize any size"
    )
    g.add_argument(
        "--backend",
        choices=("auto", "opencl", "numpy"),
        default="auto",
        help="auto (default): OpenCL on a device that passed the self-test, else numpy",
    )
    g = p.add_argument_group("source and metrics")
    g.add_argument(
        "--source-size",
        type=size_arg,
        default=None,
        metavar="WxH",
        help="resize the source frames (default: as stored, or as the database recorded)",
    )
    g.add_argument("--window", type=positive_int, default=25, help="frames per stability window (default 25)")
    g.add_argument(
        "--downscale",
        type=positive_int,
        default=None,
        help="downscale factor for spectrum and patches (default min(H, W) // 128, at least 1)",
    )
    g.add_argument("--samples", type=positive_int, default=1000, help="patches sampled per direction (default 1000)")
    return p


# -- argument parsing ---------------------------------------------------------------------------
_GRID = re.compile(r"^grid:(\d+)x(\d+)(?:\+(\d+)\+(\d+))?$", re.IGNORECASE)


def parse_events(text: str, n_frames: int) -> list[int]:
    """``"10,20"`` or ``"every:10"`` -> frame indices (checked against ``n_frames``)."""
    text = text.strip()
    if text.lower().startswith("every:"):
        try:
            step = int(text[6:])
        except ValueError:
            raise UsageError(f"--events every:N needs an integer N, not {text!r}") from None
        if step < 1:
            raise UsageError(f"--events every:N needs N >= 1, not {step}")
        events = list(range(step, n_frames, step))
        if not events:
            raise UsageError(f"--events {text}: no event inside the output's {n_frames} frames")
        return events
    try:
        events = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"--events must be comma-separated frame indices, not {text!r}") from None
    if not events:
        raise UsageError("--events names no frame")
    for e in events:
        if not 1 <= e <= n_frames - 1:
            raise UsageError(f"--events: frame {e} is outside the output's frames 1..{n_frames - 1}")
    return events


def parse_boundaries(spec: str, shape: tuple[int, int]) -> tuple[np.ndarray | None, bool, tuple[int, int] | None]:
    """``--boundaries`` -> (label map or None, wrap, the grid's period (H, W) or None) for frames
    of ``shape`` = (H, W)."""
    from ..analyzer.metrics import grid_labels

    h, w = shape
    if spec.lower() == "border":
        return None, True, None
    mt = _GRID.match(spec)
    if mt:
        tw, th = int(mt.group(1)), int(mt.group(2))
        ox, oy = int(mt.group(3) or 0), int(mt.group(4) or 0)
        if tw < 1 or th < 1:
            raise UsageError(f"--boundaries {spec}: tile size must be at least 1x1")
        labels = grid_labels((h, w), (th, tw), offset=(oy, ox))
        if labels.max() == 0:
            raise UsageError(f"--boundaries {spec}: the grid has no seam inside the {w}x{h} frame")
        return labels, False, (th, tw)
    if spec.lower().startswith("grid:"):
        raise UsageError(f"--boundaries grid must be grid:WxH or grid:WxH+X+Y, not {spec!r}")
    if not os.path.isfile(spec):
        raise UsageError(f"--boundaries {spec!r} is neither grid:WxH, border, nor an existing image file")
    import cv2

    img = cv2.imread(spec, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise UsageError(f"--boundaries {spec}: cannot read it as an image")
    if img.shape[:2] != (h, w):
        raise UsageError(
            f"--boundaries {spec}: mask is {img.shape[1]}x{img.shape[0]} but the output frames are {w}x{h}"
        )
    if img.ndim == 2:
        labels = img.astype(np.int64)
    else:
        flat = img.reshape(h * w, -1).astype(np.int64)
        labels = np.unique(flat, axis=0, return_inverse=True)[1].reshape(h, w)
    return labels, False, None


# -- inputs ------------------------------------------------------------------------------------
def _load(path: str, **opts: Any) -> np.ndarray:
    return load_clip_arg(path, **opts).frames


def play_database(args: argparse.Namespace) -> tuple[np.ndarray, dict[str, Any], tuple[int, int] | None]:
    """Frames from the player, the load options that reproduce the texture's source frames,
    and the player's cell lattice ``(th, tw)`` (mode tiles; None for other modes)."""
    from ..player import open_player, player_class

    opts: dict[str, Any] = {"seed": args.seed, "backend": args.backend}
    if args.size is not None:
        if not any(p.name == "size" for p in player_class(args.mode).options):
            raise UsageError(f"--size is not supported by mode {args.mode} (it plays at the clip's resolution)")
        opts["size"] = args.size
    known_count(player_class(args.mode), opts)
    n = args.frames or 300
    with open_player(args.output, args.texture, mode=args.mode, **opts) as player:
        src = player.texture.source
        tile = getattr(player, "tile_size", None)
        frames = np.empty((n,) + tuple(player.shape), np.uint8)
        for i in range(n):
            player.next_frame(out=frames[i])
    source_opts: dict[str, Any] = {
        "start": int(src.frame_start),
        "step": int(src.frame_step),
        "stop": int(src.frame_start + src.n_frames * src.frame_step),
        "size": (int(src.height), int(src.width)),
        "color": int(src.channels) == 3,
    }
    if src.crop:
        source_opts["crop"] = tuple(int(v) for v in src.crop)
    return frames, source_opts, (None if tile is None else (int(tile[0]), int(tile[1])))


def run(args: argparse.Namespace) -> int:
    from ..analyzer import metrics, verdicts

    is_db = args.output.lower().endswith(DB_SUFFIXES)
    if not is_db:
        for flag, val in (("--texture", args.texture), ("--size", args.size)):
            if val is not None:
                raise UsageError(f"{flag} applies to a database output (.h5), not to {args.output}")
    tile = None
    if is_db:
        output, source_opts, tile = play_database(args)
    else:
        output = _load(args.output, **({"stop": args.frames} if args.frames else {}))
        source_opts = {}
    if args.source_size is not None:
        source_opts["size"] = args.source_size
    source = _load(args.source, **source_opts)
    t, h, w = output.shape[:3]
    if output.shape[-1] != source.shape[-1]:  # grey against colour: compare in colour
        output, source = (np.repeat(a, 3, axis=-1) if a.shape[-1] == 1 else a for a in (output, source))
    labels, wrap, period = (None, False, None) if args.boundaries is None else parse_boundaries(args.boundaries, (h, w))
    wrap = wrap or args.wrap
    events = parse_events(args.events, t) if args.events else None
    report = metrics.evaluate(
        output,
        source,
        labels=labels,
        wrap=wrap,
        events=events,
        window=args.window,
        downscale=args.downscale,
        seed=args.seed,
        n_samples=args.samples,
        period=period,
        lattice=tile if tile is not None else period,
    )
    if args.sheet:
        from ..analyzer.sheet import contact_sheet

        title = f"{args.mode} {os.path.basename(args.output)}" if is_db else os.path.basename(args.output)
        try:
            contact_sheet(source, output, args.sheet, title=title)
        except (OSError, ValueError) as e:
            raise UsageError(f"--sheet {args.sheet}: cannot write it: {e}") from None
        report["sheet"] = args.sheet
    report["verdicts"] = verdicts.judge(report)
    report["verdict"] = verdicts.worst(report["verdicts"])
    report["source"] = args.source
    report["output"] = args.output
    if is_db:
        report["player"] = {
            "texture": args.texture,
            "mode": args.mode,
            "seed": args.seed,
            "frames": int(t),
            "backend": args.backend,
        }
    if args.json:
        print(json.dumps(report, indent=2, allow_nan=False))
    else:
        print(format_table(report))
    if args.strict and report["verdict"] not in ("good", verdicts.NA):
        bad = [v["figure"] for v in report["verdicts"] if v["verdict"] not in ("good", verdicts.NA)]
        print(f"dynatex: evaluate --strict: out of the good range: {', '.join(bad)}", file=sys.stderr)
        return STRICT_EXIT
    return 0


# -- the readable table ----------------------------------------------------------------------------
def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return "nan" if not math.isfinite(v) else f"{v:.{digits}f}"
    return str(v)


def format_table(report: dict[str, Any]) -> str:
    """The report as aligned ``metric  value  good  verdict`` lines, then the overall verdict.

    A figure that :mod:`~dynatex.analyzer.verdicts` judges shows its good range and verdict; the
    others show what good looks like in words.
    """
    rows: list[tuple[str, str, str, str | None]] = []  # metric, value, good, figure judged
    st = report.get("stability")
    same = "n/a: output size differs from the source"
    if st is None:
        rows.append(("stability energy ratio", same, "", None))
    else:
        lo, hi = st["bounds"]
        rows.append(
            (
                "stability energy ratio min/max",
                f"{_fmt(st['min_ratio'])} / {_fmt(st['max_ratio'])}",
                f"{_fmt(lo, 2)}..{_fmt(hi, 2)} every window",
                "stability",
            )
        )
        rows.append(("stability final window", _fmt(st["final_ratio"]), "about 1", None))
        rows.append(("mean energy ratio", "", "", "energy_ratio"))
        rows.append(("non-finite frames", str(st["nonfinite_frames"]), "0", None))
        if st["nonfinite_frames"]:
            rows.append(("other metrics", "skipped: the output holds NaN/inf", "", None))
    if "frame_step_ratio" in report:
        lp = report.get("lattice_prominence")
        if lp is not None:
            out, src = (
                "n/a: frame too small for the lags" if v is None else _fmt(v) for v in (lp["output"], lp["source"])
            )
            rows.append(
                (
                    f"lattice prominence at {lp['tile'][1]}x{lp['tile'][0]} cells",
                    out,
                    f"<= 0.03, near the source's ({src}); a visible grid 0.1..1",
                    "lattice_prominence",
                )
            )
        sv = report["seam_visibility"]
        rows.append(
            (
                "seam visibility mean/max",
                "n/a (no --boundaries)" if sv is None else f"{_fmt(sv['mean'])} / {_fmt(sv['max'])}",
                "about 1 (> 1.5 visible)",
                "seam_visibility",
            )
        )
        td = report["temporal_discontinuity"]
        rows.append(
            (
                "temporal discontinuity max",
                "n/a (no --events)" if td is None else f"{_fmt(td['max'])} over {len(td['events'])} events",
                "about 1 (> 2 a visible jump)",
                "temporal_discontinuity",
            )
        )
        rows.append(
            ("frame step ratio", _fmt(report["frame_step_ratio"]), "about 1 (0 frozen, >> 1 jumpy)", "frame_step_ratio")
        )
        rows.append(
            (
                "spectrum distance (dB)",
                _fmt(report["spectrum_distance_db"], 2),
                "< 1 good, > 3 unlike",
                "spectrum_distance_db",
            )
        )
        rows.append(("patch coherence (grey levels)", _fmt(report["patch_coherence"], 2), "low (0 = copies)", None))
        rows.append(
            ("patch completeness (grey levels)", _fmt(report["patch_completeness"], 2), "low (0 = all used)", None)
        )
        cov = report["frame_coverage"]
        rows.append(
            (
                "frame coverage",
                same if cov is None else _fmt(cov),
                "near 1 for a player of frames",
                "frame_coverage",
            )
        )
        nov = report.get("local_novelty")
        rows.append(
            (
                "local novelty (mixed positions)",
                (same if report["output_size"] != report["source_size"] else "n/a: no moving region")
                if nov is None
                else _fmt(nov, 2),
                "",
                "local_novelty",
            )
        )
        lag = report["repetition_lag"]
        rows.append(
            ("repetition lag (frames)", "none found" if lag is None else str(lag), "none, or long", "repetition_lag")
        )
        lat = report.get("lattice_correlation")
        if lat is not None:
            out, src = (
                "n/a: frame not larger than the grid" if v is None else " / ".join(_fmt(x, 2) for x in v)
                for v in (lat["output"], lat["source"])
            )
            rows.append(
                (
                    f"lattice correlation y/x at {lat['period'][1]}x{lat['period'][0]}",
                    out,
                    f"near the source's ({src})",
                    None,
                )
            )
    judged = {v["figure"]: v for v in report.get("verdicts", ())}
    lines_in: list[tuple[str, str, str, str]] = []
    for metric, value, good, figure in rows:
        v = judged.get(figure) if figure else None
        if v is None:
            if figure == "energy_ratio":
                continue
            lines_in.append((metric, value, good, ""))
            continue
        if figure == "energy_ratio":
            value = _fmt(v["value"])
        lines_in.append((metric, value, v["good"], v["verdict"]))
    head = (
        f"{report['output']} ({report['output_frames']} frames, {report['output_size'][1]}x"
        f"{report['output_size'][0]}) against {report['source']} ({report['source_frames']} frames, "
        f"{report['source_size'][1]}x{report['source_size'][0]})"
    )
    w0 = max(len(r[0]) for r in lines_in)
    w1 = max(len(r[1]) for r in lines_in)
    w2 = max(len(r[2]) for r in lines_in)
    lines = [head, f"{'metric':<{w0}}  {'value':<{w1}}  {'good':<{w2}}  verdict", "-" * (w0 + w1 + w2 + 13)]
    lines += [f"{a:<{w0}}  {b:<{w1}}  {c:<{w2}}  {d}".rstrip() for a, b, c, d in lines_in]
    if "verdict" in report:
        lines.append(f"overall: {report['verdict']} (the worst verdict; analyzer/METRICS.md gives the ranges)")
    return "\n".join(lines)
