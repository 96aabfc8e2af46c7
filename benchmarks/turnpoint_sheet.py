"""A contact sheet of every distinct turn-point jump a played texture takes: one row per jump
(source -> destination, forward or mirrored backward), the frame before the jump and the
crossfade after it, each labelled with its :func:`double_image` over the source's level.

    python benchmarks/turnpoint_sheet.py CLIP OUT.png [--frames 4000] [--seed 0] [--model] [--analyze OPTIONS]

``--model`` adds a row for every transition the analysis kept, forward and mirrored, drawn
from the source frames as the player blends them (the frame before, then the crossfade);
labels are output frame: double image over the source's level (red above it).

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
    ap.add_argument("--model", action="store_true", help="also every transition of the model, both ways")
    ap.add_argument("--analyze", default="", help="extra analysis options, e.g. '--tp-max-ghost 0 --tp-warp off'")
    args = ap.parse_args()
    double_image, double_image_level = _measures()
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "t.h5")
        cmd = [
            sys.executable,
            "-m",
            "dynatex",
            "analyze",
            args.clip,
            "-o",
            db,
            "--methods",
            "turnpoints",
            "-q",
            *args.analyze.split(),
        ]
        subprocess.run(cmd, check=True, cwd=tmp)
        with open_player(db, mode="turnpoints", seed=args.seed, backend="numpy") as p:
            idx, ev = p.advance(args.frames)
            model_src, model_dst = p.model.src.tolist(), p.model.dst.tolist()
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
                rows.append(_row(frames, ks, f"jump {a} -> {b} at output frame {e}", source, level, double_image))
            if args.model:  # every transition of the model, forward and mirrored, as the player draws it
                t = len(source)
                ms = range(1, 5)
                for i, j in zip(model_src, model_dst):
                    for label, before, old, new in (
                        (f"transition {i} -> {j} forward", i, [i + m for m in ms], [j + m - 1 for m in ms]),
                        (
                            f"its mirror {j + 1} -> {i + 1} backward",
                            j + 1,
                            [j + 1 - m for m in ms],
                            [i + 2 - m for m in ms],
                        ),
                    ):
                        ok = [
                            (o, n, round(256 * m / 5))
                            for m, (o, n) in enumerate(zip(old, new), 1)
                            if 0 <= o < t and 0 <= n < t
                        ]
                        frames = [source[min(before, t - 1)]]
                        for o, n, w in ok:
                            out = np.empty_like(source[0])
                            p.engine.render(((n, w), (o, 256 - w)), out)  # warped where the model has the flow
                            frames.append(out)
                        ks = list(range(len(frames)))
                        rows.append(_row(np.stack(frames), ks, label, source, level, double_image))
    sheet = np.concatenate(rows) if rows else np.full((20, 400, 3), 255, np.uint8)
    cv2.imwrite(args.out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(f"{len(firsts)} distinct jumps taken, level {level:.2f}: {args.out}")


def _row(frames, ks, text, source, level, double_image) -> np.ndarray:
    ghost = double_image(frames, source)
    panels = []
    for k, f, g in zip(ks, frames, ghost):
        img = cv2.resize(f, (PANEL, PANEL), interpolation=cv2.INTER_AREA)
        img = cv2.copyMakeBorder(img, 16, 2, 2, 2, cv2.BORDER_CONSTANT, value=(255, 255, 255))
        colour = (200, 0, 0) if g > level else (0, 0, 0)
        cv2.putText(img, f"{k}: {g / level:.2f}", (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.38, colour, 1)
        panels.append(img)
    row = np.concatenate(panels, axis=1)
    width = (AFTER + 2) * panels[0].shape[1]
    row = np.pad(row, ((0, 0), (0, width - row.shape[1]), (0, 0)), constant_values=255)
    head = np.full((16, width, 3), 255, np.uint8)
    text += f"; worst ghost {ghost.max() / level:.2f} x the source's level"
    cv2.putText(head, text, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
    return np.concatenate([head, row])


if __name__ == "__main__":
    main()
