"""``dynatex demo``: the whole path on a built-in sample, in well under two minutes.

Makes sample clips, analyzes them, plays every demo step below (edits included), writes a
video and a contact sheet, and prints a short benchmark. To show a new mode, add its
analysis method to a texture of ``DEMO_TEXTURES`` (or a new sample) and its steps to
``DEMO_STEPS``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..analyzer.methods import METHODS
from ..analyzer.video import load_clip
from ..player import open_player
from ..sample import ripples
from ..tiledb import DatabaseWriter
from . import COMMANDS
from ._common import seed


@dataclass(frozen=True)
class DemoStep:
    title: str
    mode: str
    controls: dict = field(default_factory=dict)  # player attributes set before playing
    options: dict = field(default_factory=dict)  # player constructor options
    frames: int = 48
    texture: str = "ripples"


def _pendulum() -> np.ndarray:
    from ..analyzer.turnpoints import pendulum_clip

    return pendulum_clip(120, 96)[0]


def _spreading() -> np.ndarray:
    from ..analyzer.quilt import spreading_clip

    return spreading_clip(48, 48, 64)


def _left_fast() -> np.ndarray:
    from ..player.modes.ratemap import halves

    return halves((96, 128), 2.0, 1.0)


def _grassy_other() -> list[np.ndarray]:
    return [np.ascontiguousarray(ripples()[..., ::-1])]


#: The demo's textures: a sample-clip maker and the analysis methods (with options) run on it.
#: An option given as a callable is made when the demo runs, not when this module is imported
#: (every ``dynatex`` command imports it to build its parser).
DEMO_TEXTURES: dict[str, tuple[Callable[[], np.ndarray], dict[str, dict]]] = {
    "ripples": (
        ripples,
        {
            "lds": {"n": 40},
            "mixture": {"components": 3, "dim": 8},
        },
    ),
    "pendulum": (
        _pendulum,
        {
            "turnpoints": {},
        },
    ),
    "grassy": (
        ripples,
        {
            "tiles": {"tile": 32, "n_tiles": 3, "min_loop": 24, "mix": _grassy_other, "names": ["grassy", "sea"]},
        },
    ),
    "spreading": (
        _spreading,
        {
            "quilt": {"size": (96, 128), "block": 16, "rank": 15},
        },
    ),
}

#: What the demo plays, in order.
DEMO_STEPS: list[DemoStep] = [
    DemoStep("lds: as learned", "lds"),
    DemoStep("lds: speed 2", "lds", {"speed": 2.0}),
    DemoStep("lds: reversed", "lds", {"speed": -1.0}),
    DemoStep("lds: slow, calm", "lds", {"speed": 0.5, "intensity": 0.5}),
    DemoStep("lds: fine scales up", "lds", {"scales": (0.5, 1.0, 2.5)}),
    DemoStep("lds: float16 basis", "lds", options={"precision": "float16"}),
    DemoStep("mixture: as learned", "mixture"),
    DemoStep("mixture: calm", "mixture", {"intensity": 0.5}),
    DemoStep("turnpoints: turns + jumps", "turnpoints", texture="pendulum"),
    DemoStep("turnpoints: jumps, speed 1.5", "turnpoints", {"speed": 1.5}, {"playback": "jumps"}, texture="pendulum"),
    DemoStep(
        "tiles: random arrangement, smoothed offsets", "tiles", {"sigma": 16.0}, {"size": (96, 128)}, texture="grassy"
    ),
    DemoStep(
        "tiles: two textures mixed, consensus tone",
        "tiles",
        {},
        {"size": (96, 128), "labels": "halves", "tone": "consensus"},
        texture="grassy",
    ),
    DemoStep("evolve: quilted 2x, jitter 3", "evolve", {"jitter": 3.0}, texture="spreading"),
    DemoStep(
        "evolve: left half 2x faster, smoothed",
        "evolve",
        {"rate_map": _left_fast(), "rate_sigma": 8.0},
        texture="spreading",
    ),
]


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "demo",
        help=COMMANDS["demo"],
        description="The embedded default: make a sample clip, analyze it, play it with "
        "several edits, write demo.mp4 and contact_sheet.png, print a short benchmark.",
    )
    p.add_argument("-o", "--output", default="dynatex-demo", help="output folder (default ./dynatex-demo)")
    p.add_argument(
        "--backend",
        choices=("auto", "opencl", "numpy"),
        default="auto",
        help="auto (default): OpenCL on a device that passed the self-test, else numpy",
    )
    p.add_argument("--seed", type=seed, default=0, help="random seed of the players, %(type)s (default 0)")
    return p


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    os.makedirs(args.output, exist_ok=True)
    db = os.path.join(args.output, "sample.h5")
    with DatabaseWriter(db, overwrite=True) as w:
        for name, (make, methods) in DEMO_TEXTURES.items():
            clip = load_clip(make())
            clip.filename = f"{name} (built-in sample)"
            t, h, wd, _ = clip.frames.shape
            print(f"sample {name!r}: {t} frames {wd}x{h}")
            w.put_texture(name, clip.source_info())
            if any(METHODS[m].needs_frames for m in methods):
                w.put_frames(name, clip.frames)
            for m, options in methods.items():
                options = {k: v() if callable(v) else v for k, v in options.items()}
                t0m = time.perf_counter()
                w.put_method(name, m, METHODS[m].function()(clip, **options))
                print(f"  analyzed {m} in {time.perf_counter() - t0m:.2f} s")
    print(f"wrote {db}")
    video_hw = (96, 128)
    fps = 25.0

    from ._output import FrameWriter

    video = FrameWriter(os.path.join(args.output, "demo.mp4"))
    video.open(video_hw, fps)
    rows = []
    used: list[str] = []  # under "auto" each mode takes the engine the self-test measured faster here
    for step in DEMO_STEPS:
        with open_player(db, step.texture, mode=step.mode, backend=args.backend, seed=args.seed, **step.options) as p:
            if p.backend not in used:
                used.append(p.backend)
                print(f"player backend ({step.mode}): {_backend_line(p)}")
            for key, value in step.controls.items():
                setattr(p, key, value)
            shown = [p.next_frame() for _ in range(step.frames)]
        for f in shown:
            video.write(_fit(f, video_hw))
        rows.append((step.title, shown[:: max(1, step.frames // 6)][:6]))
        print(f"played {step.title!r}: {step.frames} frames")
    video.close()
    sheet = os.path.join(args.output, "contact_sheet.png")
    _contact_sheet(rows, sheet)
    print(f"wrote {video.output} and {sheet}")

    _short_benchmark(db, "opencl" if "opencl" in used else "numpy")
    print(f"demo finished in {time.perf_counter() - t0:.1f} s")
    return 0


def _backend_line(p) -> str:
    if p.backend == "numpy":
        return (
            "numpy (no OpenCL device passed the self-test, or it measured slower here; "
            "`python -m dynatex.player --check` says which)"
        )
    d = p.ctx.devices[0]
    return f"OpenCL on {d.platform.name.strip()} / {d.name.strip()}"


def _fit(frame: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Frames of every step go into one video: scale to fit ``hw``, letterboxed."""
    if frame.shape[:2] == tuple(hw):
        return frame
    import cv2

    scale = min(hw[0] / frame.shape[0], hw[1] / frame.shape[1])
    size = (max(1, round(frame.shape[1] * scale)), max(1, round(frame.shape[0] * scale)))
    small = cv2.resize(frame, size, interpolation=cv2.INTER_AREA)
    out = np.zeros((*hw, 3), np.uint8)
    y, x = (hw[0] - size[1]) // 2, (hw[1] - size[0]) // 2
    out[y : y + size[1], x : x + size[0]] = small
    return out


def _contact_sheet(rows: list[tuple[str, list[np.ndarray]]], path: str, thumb_h: int = 96) -> None:
    import cv2

    label_w = 220
    lines = []
    for title, frames in rows:
        thumbs = [cv2.resize(f, (int(f.shape[1] * thumb_h / f.shape[0]), thumb_h)) for f in frames]
        strip = np.concatenate(thumbs, axis=1)
        label = np.full((thumb_h, label_w, 3), 255, np.uint8)
        cv2.putText(label, title, (6, thumb_h // 2 + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        lines.append(np.concatenate([label, strip], axis=1))
    width = max(line.shape[1] for line in lines)
    lines = [np.pad(line, ((0, 4), (0, width - line.shape[1]), (0, 0)), constant_values=255) for line in lines]
    if not cv2.imwrite(path, cv2.cvtColor(np.concatenate(lines, axis=0), cv2.COLOR_RGB2BGR)):
        raise OSError(f"cannot write {path}")


def _short_benchmark(db: str, backend: str) -> None:
    from ..benchmark import bench_player, copy_bandwidth, format_result

    if backend != "opencl":
        print("benchmark skipped: it compares the OpenCL player with the numpy reference")
        return
    bw = copy_bandwidth(mbytes=64, repeats=3)
    print(f"benchmark (copy bandwidth {bw['gbs']:.1f} GB/s):")
    seen = set()
    for step in DEMO_STEPS:
        key = (step.mode, tuple(sorted(step.options.items())))
        if key in seen:
            continue
        seen.add(key)
        r = bench_player(db, step.texture, mode=step.mode, frames=100, bandwidth_gbs=bw["gbs"], options=step.options)
        print("  " + format_result(r) + (f" [{step.options}]" if step.options else ""))
    from ..benchmark import bench_lds_sizes

    bench_lds_sizes([(288, 352)], frames=60, precisions=("float32",), log=lambda line: print("  " + line), bandwidth=bw)
    sys.stdout.flush()
