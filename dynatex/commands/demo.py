"""``dynatex demo``: the whole path on a built-in sample, in well under two minutes.

Makes a sample clip, analyzes it, plays every demo step below (edits included), writes a
video and a contact sheet, and prints a short benchmark. To show a new mode, add its
analysis method to ``DEMO_METHODS`` and its steps to ``DEMO_STEPS``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ..analyzer.methods import METHODS
from ..analyzer.video import load_clip
from ..player import open_player
from ..sample import ripples
from ..tiledb import DatabaseWriter


@dataclass(frozen=True)
class DemoStep:
    title: str
    mode: str
    controls: dict = field(default_factory=dict)   # player attributes set before playing
    options: dict = field(default_factory=dict)    # player constructor options
    frames: int = 48


#: Analysis methods the demo runs on the sample (with their learn options).
DEMO_METHODS: dict[str, dict] = {
    "lds": {"n": 40},
    # the ripples travel and barely mirror (symmetry <= 0.05): keep every local maximum as a turn point
    "turnpoints": {"min_symmetry": 0.0},
    "mixture": {"components": 3, "dim": 8},
}

#: What the demo plays, in order.
DEMO_STEPS: list[DemoStep] = [
    DemoStep("lds: as learned", "lds"),
    DemoStep("lds: speed 2", "lds", {"speed": 2.0}),
    DemoStep("lds: reversed", "lds", {"speed": -1.0}),
    DemoStep("lds: slow, calm", "lds", {"speed": 0.5, "intensity": 0.5}),
    DemoStep("lds: fine scales up", "lds", {"scales": (0.5, 1.0, 2.5)}),
    DemoStep("lds: float16 basis", "lds", options={"precision": "float16"}),
    DemoStep("mixture: 16 draws", "mixture"),
    DemoStep("mixture: plain AR, calm", "mixture", {"draws": 1, "intensity": 0.5}),
    DemoStep("turnpoints: turns + jumps", "turnpoints"),
    DemoStep("turnpoints: jumps, speed 1.5", "turnpoints", {"speed": 1.5}, {"playback": "jumps"}),
]


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("demo", help="analyze a built-in sample, play every mode, write a video and a contact sheet",
                       description="The embedded default: make a sample clip, analyze it, play it with "
                                   "several edits, write demo.mp4 and contact_sheet.png, print a short benchmark.")
    p.add_argument("-o", "--output", default="dynatex-demo", help="output folder (default ./dynatex-demo)")
    p.add_argument("--backend", choices=("opencl", "numpy"), default="opencl")
    p.add_argument("--seed", type=int, default=0)
    return p


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    os.makedirs(args.output, exist_ok=True)
    db = os.path.join(args.output, "sample.h5")
    frames = ripples(seed=args.seed)
    clip = load_clip(frames)
    clip.filename = "ripples (built-in sample)"
    print(f"sample clip: {frames.shape[0]} frames {frames.shape[2]}x{frames.shape[1]}")

    with DatabaseWriter(db, overwrite=True) as w:
        w.put_texture("ripples", clip.source_info())
        methods = [METHODS[m] for m in DEMO_METHODS]
        if any(m.needs_frames for m in methods):
            w.put_frames("ripples", clip.frames)
        for m in methods:
            t = time.perf_counter()
            w.put_method("ripples", m.name, m.function()(clip, **DEMO_METHODS[m.name]))
            print(f"analyzed {m.name} in {time.perf_counter() - t:.2f} s")
    print(f"wrote {db}")

    from .play import FrameWriter
    video = FrameWriter(os.path.join(args.output, "demo.mp4"))
    rows = []
    for step in DEMO_STEPS:
        with open_player(db, "ripples", mode=step.mode, backend=args.backend, seed=args.seed,
                         **step.options) as p:
            for key, value in step.controls.items():
                setattr(p, key, value)
            shown = [p.next_frame() for _ in range(step.frames)]
        for f in shown:
            video.write(_fit(f, frames.shape[1:3]), clip.fps)
        rows.append((step.title, shown[:: max(1, step.frames // 6)][:6]))
        print(f"played {step.title!r}: {step.frames} frames")
    video.close()
    sheet = os.path.join(args.output, "contact_sheet.png")
    _contact_sheet(rows, sheet)
    print(f"wrote {video.output} and {sheet}")

    _short_benchmark(db, args.backend)
    print(f"demo finished in {time.perf_counter() - t0:.1f} s")
    return 0


def _fit(frame: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Frames of every step go into one video of the sample's size."""
    if frame.shape[:2] == tuple(hw):
        return frame
    import cv2
    return cv2.resize(frame, (hw[1], hw[0]), interpolation=cv2.INTER_AREA)


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
    bw = copy_bandwidth(mbytes=64, repeats=3)
    print(f"benchmark (copy bandwidth {bw['gbs']:.1f} GB/s):")
    seen = set()
    for step in DEMO_STEPS:
        key = (step.mode, tuple(sorted(step.options.items())))
        if key in seen:
            continue
        seen.add(key)
        r = bench_player(db, "ripples", mode=step.mode, frames=100, bandwidth_gbs=bw["gbs"], options=step.options)
        print("  " + format_result(r) + (f" [{step.options}]" if step.options else ""))
    from ..benchmark import bench_lds_sizes
    bench_lds_sizes([(352, 288)], frames=60, precisions=("float32",), log=lambda line: print("  " + line),
                    bandwidth=bw)
    sys.stdout.flush()
