"""A contact sheet of every distinct turn-point jump a played texture takes: one row per jump
(source -> destination, forward or mirrored backward), the frame before the jump and the
crossfade after it, each labelled with its :func:`double_image` over the source's level.

    python benchmarks/turnpoint_sheet.py CLIP OUT.png [--frames 4000] [--seed 0]

Analyses CLIP with the installed version's ``turnpoints`` defaults (run it with another
installation's Python to draw that version's jumps).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from turnpoint_ghosts import _measures  # noqa: E402

from dynatex.player import open_player  # noqa: E402

PANEL = 128
AFTER = 5  # output frames shown after the jump (the default crossfade is 4)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clip")
    ap.add_argument("out")
    ap.add_argument("--frames", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    double_image, double_image_level = _measures()
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "t.h5")
        cmd = [sys.executable, "-m", "dynatex", "analyze", args.clip, "-o", db, "--methods", "turnpoints", "-q"]
        subprocess.run(cmd, check=True, cwd=tmp)
        with open_player(db, mode="turnpoints", seed=args.seed, backend="numpy") as p:
            idx, ev = p.advance(args.frames)
        firsts: dict[tuple[int, int], int] = {}
        for e in np.flatnonzero(ev & 2):
            if e >= 1 and e + AFTER < args.frames:
                firsts.setdefault((int(idx[e - 1]), int(idx[e])), int(e))
        with open_player(db, mode="turnpoints", seed=args.seed, backend="numpy") as p:
            source = p.texture.frames().read()
            want = {k for e in firsts.values() for k in range(e - 1, e + AFTER + 1)}
            shown = {}
            for k in range(max(want) + 1 if want else 0):
                f = p.next_frame()
                if k in want:
                    shown[k] = f
    level = double_image_level(source)
    rows = []
    for (a, b), e in sorted(firsts.items(), key=lambda kv: kv[1]):
        ks = list(range(e - 1, e + AFTER + 1))
        frames = np.stack([shown[k] for k in ks])
        ghost = double_image(frames, source)
        panels = []
        for k, f, g in zip(ks, frames, ghost):
            img = cv2.resize(f, (PANEL, PANEL), interpolation=cv2.INTER_AREA)
            img = cv2.copyMakeBorder(img, 16, 2, 2, 2, cv2.BORDER_CONSTANT, value=(255, 255, 255))
            colour = (200, 0, 0) if g > level else (0, 0, 0)
            cv2.putText(img, f"{k}: {g / level:.2f}", (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.38, colour, 1)
            panels.append(img)
        row = np.concatenate(panels, axis=1)
        head = np.full((16, row.shape[1], 3), 255, np.uint8)
        text = f"jump {a} -> {b} at output frame {e}; worst ghost {ghost.max() / level:.2f} x the source's level"
        cv2.putText(head, text, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
        rows.append(np.concatenate([head, row]))
    sheet = np.concatenate(rows) if rows else np.full((20, 400, 3), 255, np.uint8)
    cv2.imwrite(args.out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(f"{len(firsts)} distinct jumps, level {level:.2f}: {args.out}")


if __name__ == "__main__":
    main()
