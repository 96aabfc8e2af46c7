"""Flipbook export on real clips: grass (tiles) and the clock pendulum (turnpoints), and the
motion-vector blend against a plain crossfade.

    python benchmarks/flipbook_export.py [--clips ../shared/data/clips] [--json]

1. Analyses grass (tiles) and the clock (turnpoints), runs ``dynatex export --loop`` on each
   (grass also with ``--frames 64``), and checks that the atlas's size, frame count and order
   match the sidecar (every cell compared with the frame the player or the source path gives)
   and reports the wrap discontinuity (last -> first frame step over the source's median step).
2. The motion-vector check: a flipbook of every second frame of a clip; frame ``k + 1/2`` drawn
   by the numpy model of the engine shader (:func:`dynatex.analyzer.flipbook.shader_blend`) and
   by a crossfade, each compared (RMS, grey levels) with the true odd frame between them.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from _clips import CLIPS

from dynatex.analyzer import flipbook as fb
from dynatex.analyzer import load_clip
from dynatex.player import open_player


def dynatex(*argv: str) -> None:
    r = subprocess.run([sys.executable, "-m", "dynatex", *argv], capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise SystemExit(f"dynatex {' '.join(argv)} failed: {r.stderr.strip()}")


def read_atlas(folder: Path, doc: dict) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(folder / doc["files"]["color"])), cv2.COLOR_BGR2RGB)


def check_layout(atlas: np.ndarray, doc: dict, expected: np.ndarray) -> dict:
    """Size, frame count and order of ``atlas`` against the sidecar and the ``expected`` frames."""
    grid = fb.Grid(doc["cols"], doc["rows"], (doc["tile_height"], doc["tile_width"]), doc["frames"])
    size_ok = atlas.shape[:2] == (doc["atlas_height"], doc["atlas_width"]) == grid.atlas_shape
    worst = max(
        int(np.abs(atlas[grid.cell(k)].astype(int) - fb.fit(f, grid.tile).astype(int)).max())
        for k, f in enumerate(expected)
    )
    empty = all(not atlas[grid.cell(k)].any() for k in range(len(expected), grid.cols * grid.rows))
    return {
        "size_matches": bool(size_ok),
        "frames": doc["frames"],
        "expected_frames": len(expected),
        "max_cell_difference": worst,
        "empty_cells_black": empty,
    }


def export_case(db: Path, out: Path, mode: str, extra: list[str], expected) -> dict:
    t0 = time.perf_counter()
    dynatex("export", str(db), "-o", str(out), "--mode", mode, "--loop", *extra)
    seconds = time.perf_counter() - t0
    doc = json.loads(next(out.glob("*.json")).read_text())
    row = {
        "mode": mode,
        "options": " ".join(extra),
        "grid": f"{doc['cols']}x{doc['rows']}",
        "tile": f"{doc['tile_width']}x{doc['tile_height']}",
        "loop": doc["loop"],
        "fps": round(doc["fps"], 3),
        "wrap_discontinuity": doc["wrap_discontinuity"],
        "seconds": round(seconds, 1),
        "mv_strength_tile_uv": doc.get("motion_vectors", {}).get("strength_tile_uv"),
    }
    row.update(check_layout(read_atlas(out, doc), doc, expected(doc)))
    return row


def tiles_frames(db: Path):
    def frames(doc: dict) -> np.ndarray:
        with open_player(db, mode="tiles", backend="numpy", seed=0) as p:
            p.epoch = 0
            p.speed = p.loop_length / doc["frames"]
            return np.stack([p.next_frame().copy() for _ in range(doc["frames"])])

    return frames


def swing_frames(db: Path):
    def frames(doc: dict) -> np.ndarray:
        a, b = (int(v) for v in doc["loop"].split("turn points ")[1].split(" and back")[0].split(" and "))
        with open_player(db, mode="turnpoints", backend="numpy") as p:
            src = p.texture.frames().read()
        path = list(range(a, b + 1)) + list(range(b - 1, a, -1))
        return src[path]

    return frames


def motion_check(clip: np.ndarray, *, step: int = 2, count: int = 64) -> dict:
    """Engine motion-vector blend vs crossfade at half-way, against the true in-between frames."""
    frames = clip[: step * count + 1]
    key = frames[::step]
    n = len(key)
    grid = fb.choose_grid(n, key.shape[1:3], pow2=False)
    uv = fb.flow_to_uv(fb.frame_motion(fb.optical_flow(key, wrap=False), wrap=False))
    color = fb.color_atlas(key, grid)
    vectors, strength = fb.vector_atlas(uv, grid)

    def rms(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.sqrt(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))

    mv, xf = [], []
    for k in range(n - 1):
        truth = frames[k * step + step // 2]
        mv.append(rms(fb.shader_blend(color, vectors, grid, strength, k, 0.5), truth))
        xf.append(rms(fb.crossfade(color, grid, k, 0.5), truth))
    mv_a, xf_a = np.array(mv), np.array(xf)
    return {
        "pairs": n - 1,
        "step": step,
        "motion_blend_rms": round(float(mv_a.mean()), 3),
        "crossfade_rms": round(float(xf_a.mean()), 3),
        "motion_blend_better_share": round(float(np.mean(mv_a < xf_a)), 3),
        "strength_tile_uv": round(strength, 5),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", default=str(CLIPS))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    clips = Path(args.clips)
    grass, clock = clips / "grass_straw_wind_dyntex.avi", clips / "pendulum_clock_schoedl.mov"
    flag = clips / "flag_wind_dyntex_571c110.avi"
    if not (grass.exists() and clock.exists() and flag.exists()):
        raise SystemExit(f"the clips are not in {clips}")
    results: dict = {"export": [], "motion_vectors": {}}
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        dynatex("analyze", str(grass), "-o", str(tmp_path / "grass.h5"), "--name", "grass", "--methods", "tiles", "-q")
        dynatex(
            "analyze", str(clock), "-o", str(tmp_path / "clock.h5"), "--name", "clock", "--methods", "turnpoints", "-q"
        )
        for i, (db, mode, extra, expected) in enumerate(
            [
                (tmp_path / "grass.h5", "tiles", ["--source", str(grass)], tiles_frames(tmp_path / "grass.h5")),
                (
                    tmp_path / "grass.h5",
                    "tiles",
                    ["--source", str(grass), "--frames", "64"],
                    tiles_frames(tmp_path / "grass.h5"),
                ),
                (tmp_path / "clock.h5", "turnpoints", [], swing_frames(tmp_path / "clock.h5")),
            ]
        ):
            row = export_case(db, tmp_path / f"out{i}", mode, extra, expected)
            results["export"].append(row)
            if not args.json:
                print(json.dumps(row), flush=True)
    for name, path in (("flag", flag), ("grass", grass), ("clock", clock)):
        row = motion_check(load_clip(str(path)).frames, count=64 if name != "clock" else 21)
        results["motion_vectors"][name] = row
        if not args.json:
            print(name, json.dumps(row), flush=True)
    if args.json:
        print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
