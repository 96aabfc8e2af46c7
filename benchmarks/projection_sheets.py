"""Contact sheets and frame strips of the projection modes, from the databases
``quality_projection.py`` leaves in its OUTDIR.

Per clip, ``{clip}_look.png``: three moments, each the source frame, the output after 1,000
frames and (``lds``) the output after 1,000 frames at speed 2; and ``{clip}_strip.png``: 16
consecutive source frames above the 16 consecutive output frames (of 300 after a 50-frame
warm-up) around the largest change of mean brightness, where a whole-frame jump shows as a frame
brighter or darker than the one before. Prints, per clip, the
largest frame-to-frame change of the mean brightness over 300 output frames beside the source's.
Any dynatex checkout's interpreter can play (before and after).

    python benchmarks/projection_sheets.py OUTDIR [--clips sea,flag,ocean64,waterfall64]
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
from quality_projection import CASES, CLIPS

GAP = 4


def _scaled(frame: np.ndarray, scale: int) -> np.ndarray:
    f = frame if frame.ndim == 3 else frame[..., None]
    f = np.repeat(f, 3, axis=2) if f.shape[2] == 1 else f[..., :3]
    return np.repeat(np.repeat(f, scale, axis=0), scale, axis=1)


def _grid(rows: list[list[np.ndarray]], scale: int) -> np.ndarray:
    """Frames laid out in rows (white gaps), each pixel ``scale`` x ``scale``."""
    cells = [[_scaled(f, scale) for f in row] for row in rows]
    h, w = cells[0][0].shape[:2]
    cols = max(len(r) for r in cells)
    out = np.full((len(cells) * (h + GAP) - GAP, cols * (w + GAP) - GAP, 3), 255, np.uint8)
    for i, row in enumerate(cells):
        for j, c in enumerate(row):
            out[i * (h + GAP) : i * (h + GAP) + h, j * (w + GAP) : j * (w + GAP) + w] = c
    return out


def run_case(name: str, outdir: str) -> dict:
    from PIL import Image

    from dynatex.analyzer.video import load_clip_path
    from dynatex.player.modes.lds import LDSPlayer
    from dynatex.player.modes.mixture import MixturePlayer

    clip_file, method, *_ = CASES[name]
    src = load_clip_path(os.path.join(CLIPS, clip_file)).frames
    db = os.path.join(outdir, f"{name}.h5")
    cls = LDSPlayer if method == "lds" else MixturePlayer
    with cls(db, seed=1, backend="numpy") as p:
        for _ in range(50):
            p.next_frame()
        first = np.stack([p.next_frame() for _ in range(300)])
        p.advance(1000 - 350)
        at = np.stack([p.next_frame() for _ in range(16)])
    fast = None
    if method == "lds":
        with cls(db, seed=1, backend="numpy") as p:
            p.speed = 2.0
            p.advance(1000)
            fast = np.stack([p.next_frame() for _ in range(16)])
    scale = max(1, 256 // src.shape[1])
    moments = [0, 7, 15]
    look = [[src[(k * 5) % len(src)], at[k]] + ([fast[k]] if fast is not None else []) for k in moments]
    Image.fromarray(_grid(look, scale)).save(os.path.join(outdir, f"{name}_look.png"))

    def jumps(frames: np.ndarray) -> np.ndarray:
        return np.abs(np.diff(frames.reshape(len(frames), -1).mean(axis=1, dtype=np.float64)))

    k = int(np.clip(np.argmax(jumps(first)) - 7, 0, len(first) - 16))
    strip_scale = max(1, 96 // src.shape[1])
    Image.fromarray(_grid([list(src[:16]), list(first[k : k + 16])], strip_scale)).save(
        os.path.join(outdir, f"{name}_strip.png")
    )
    return {
        "clip": name,
        "strip_from": 50 + k,
        "brightness_jump_max": float(jumps(first).max()),
        "source_brightness_jump_max": float(jumps(src).max()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("--clips", default="sea,flag,ocean64,waterfall64")
    args = ap.parse_args()
    for name in args.clips.split(","):
        print(json.dumps(run_case(name, args.outdir)), flush=True)


if __name__ == "__main__":
    main()
