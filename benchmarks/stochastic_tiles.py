"""Mode tiles above the torus's size: the stochastic layout against the torus laid edge to edge.

    python benchmarks/stochastic_tiles.py CLIP [CLIP ...] [--sizes 1920x1080,3840x2160]
        [--frames 8] [--fps 1280x720,3840x2160] [--sheets DIR] [--db-dir DIR] [--json]

For every clip (analyzed once with the defaults, tiles only; ``--db-dir`` keeps the databases)
and every size, plays ``--frames`` frames with ``layout="torus"`` (the drawing before the
stochastic layout existed) and with ``layout="stochastic"`` and prints, per layout:

- ``autocorr``: the largest normalised autocorrelation at shifts of 64 px or more
  (:func:`tiles_quality.far_autocorrelation`), median over frames; ``src``: the source's.
- ``lattice``: :func:`dynatex.analyzer.metrics.lattice_prominence` at the stored tile size.
- ``seams``: :func:`dynatex.analyzer.metrics.seam_visibility` across the cell lattice; for the
  stochastic layout also ``window_seams``, across the borders between windows (the middle of
  the blend bands, :func:`dynatex.player.engines.stochastic_reference.window_labels`).
- ``straight``: :func:`tiles_quality.straight_edges` of output and source.
- ``contrast``: the output's luma standard deviation over the source's (a washed-out blend
  falls below 1).

``--fps`` sizes: frames per second of both layouts (best of five runs of a few frames,
alternating, in one process on the default device) and the CPU time a frame of each, the figure
that a loaded machine leaves comparable. ``--sheets``: a contact sheet per clip and
size and layout (source frames beside output frames).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from tiles_quality import far_autocorrelation, straight_edges  # noqa: E402

from dynatex.analyzer.metrics import grid_labels, lattice_prominence, seam_visibility  # noqa: E402
from dynatex.analyzer.sheet import contact_sheet  # noqa: E402
from dynatex.analyzer.tiles import learn_tiles  # noqa: E402
from dynatex.analyzer.video import load_clip_path  # noqa: E402
from dynatex.player.engines.stochastic_reference import window_labels  # noqa: E402
from dynatex.player.modes.tiles import TilesPlayer  # noqa: E402
from dynatex.tiledb import DatabaseWriter  # noqa: E402

LAYOUTS = ("torus", "stochastic")


def _size(text: str) -> tuple[int, int]:
    w, h = (int(v) for v in text.lower().split("x"))
    return h, w


def _luma_std(frames: np.ndarray) -> float:
    return float((frames[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])).std())


def figures(db: str, src: np.ndarray, size: tuple[int, int], frames: int, sheets: Path | None, name: str) -> list:
    rows = []
    sidx = np.unique(np.linspace(0, len(src) - 1, 4).round().astype(int))
    src_shift = min(64, min(src.shape[1:3]) // 4)
    src_auto = float(np.median([far_autocorrelation(src[i], src_shift) for i in sidx]))
    src_straight = straight_edges(src[sidx])
    for layout in LAYOUTS:
        with TilesPlayer(db, size=size, seed=3, layout=layout) as p:
            out = np.stack([p.next_frame() for _ in range(frames)])
            cell = p.tile_size
            windows = window_labels(size, p.engine.cell) if layout == "stochastic" else None
        idx = np.unique(np.linspace(0, len(out) - 1, 2 if size[0] * size[1] > 4e6 else 4).round().astype(int))
        res = {
            "clip": name,
            "size": f"{size[1]}x{size[0]}",
            "layout": layout,
            "autocorr": float(np.median([far_autocorrelation(out[i]) for i in idx])),
            "autocorr_src": src_auto,
            "lattice": lattice_prominence(out, cell, max_frames=4),
            "seams": float(np.median(seam_visibility(out[idx], grid_labels(size, cell)))),
            "straight": straight_edges(out[idx]),
            "straight_src": src_straight,
            "contrast": _luma_std(out[idx]) / max(_luma_std(src[sidx]), 1e-9),
        }
        if windows is not None:
            res["window_seams"] = float(np.median(seam_visibility(out[idx], windows)))
        rows.append(res)
        if sheets is not None:
            sheets.mkdir(parents=True, exist_ok=True)
            path = sheets / f"{Path(db).stem}_{res['size']}_{layout}.png"
            contact_sheet(src, out, str(path), rows=2, title=f"tiles {res['size']} {layout} {name}")
    return rows


def _cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def frame_rates(db: str, size: tuple[int, int], name: str) -> dict:
    """Both layouts' frame rates (wall clock, best of 5) and CPU time a frame (every thread of the
    process, the OpenCL CPU device's included; median of 5): on a loaded machine the wall clock
    waits for other processes, the CPU time counts the work."""
    best = dict.fromkeys(LAYOUTS, 0.0)
    cpu: dict[str, list[float]] = {layout: [] for layout in LAYOUTS}
    n = 12 if size[0] * size[1] < 2e6 else 4
    players = {layout: TilesPlayer(db, size=size, seed=3, layout=layout) for layout in LAYOUTS}
    try:
        outs = {layout: np.empty(p.shape, np.uint8) for layout, p in players.items()}
        for layout, p in players.items():
            p.next_frame(out=outs[layout])
        for _ in range(5):
            for layout, p in players.items():
                t0, c0 = time.perf_counter(), _cpu_seconds()
                for _ in range(n):
                    p.next_frame(out=outs[layout])
                best[layout] = max(best[layout], n / (time.perf_counter() - t0))
                cpu[layout].append((_cpu_seconds() - c0) / n)
    finally:
        for p in players.values():
            p.close()
    ms = {layout: 1e3 * float(np.median(v)) for layout, v in cpu.items()}
    return {
        "clip": name,
        "size": f"{size[1]}x{size[0]}",
        "fps_torus": best["torus"],
        "fps_stochastic": best["stochastic"],
        "ratio": best["stochastic"] / best["torus"],
        "cpu_ms_torus": ms["torus"],
        "cpu_ms_stochastic": ms["stochastic"],
        "cpu_ratio": ms["torus"] / ms["stochastic"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clips", nargs="+")
    ap.add_argument("--sizes", default="1920x1080,3840x2160")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--fps", default="", help="sizes to time, e.g. 1280x720,3840x2160")
    ap.add_argument("--sheets", type=Path, help="write contact sheets here")
    ap.add_argument("--db-dir", type=Path, help="keep (and reuse) the databases here")
    ap.add_argument("--block", type=int, help="quilt block size of the analysis (default: the analyzer's)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.db_dir or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for clip_path in args.clips:
            name = Path(clip_path).name
            clip = load_clip_path(clip_path)
            db = folder / f"{Path(clip_path).stem}{'' if args.block is None else f'_block{args.block}'}.h5"
            if not db.exists():
                with DatabaseWriter(db, overwrite=True) as wr:
                    wr.put_texture("t", clip.source_info())
                    wr.put_method("t", "tiles", learn_tiles(clip, tile=args.block))
            rows = []
            for size in filter(None, args.sizes.split(",")):
                rows += figures(str(db), clip.frames, _size(size), args.frames, args.sheets, name)
            for size in filter(None, args.fps.split(",")):
                rows.append(frame_rates(str(db), _size(size), name))
            for res in rows:
                if args.json:
                    print(json.dumps(res), flush=True)
                else:
                    text = (f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}" for k, v in res.items())
                    print("  ".join(text), flush=True)


if __name__ == "__main__":
    main()
