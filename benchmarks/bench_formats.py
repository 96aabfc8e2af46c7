"""RGBA and BGRA frames written by the kernels against RGB frames converted by numpy.

Per mode, in alternating rounds (the same load for every variant on a shared machine):
``rgb`` (next_frame into an RGB buffer), ``rgb+numpy`` (the same plus the conversion a caller
would otherwise do: the RGB bytes copied into an RGBA buffer whose alpha is set once), and
``rgba`` / ``bgra`` (next_frame of a player opened with that format). Medians in ms and the
ratio of each format to ``rgb`` (the issue 29 floor: 0.9x on OpenCL) and to ``rgb+numpy``.
``--backend numpy`` measures the numpy references instead; ``--modes`` picks cases.

    python benchmarks/bench_formats.py [--frames 200] [--rounds 5] [--backend opencl] [--modes lds tiles] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_tiles import CLIPS, generated_clip  # noqa: E402
from bench_tiles import write_db as write_tiles_db

from dynatex.analyzer import load_clip  # noqa: E402
from dynatex.analyzer.mixture import learn_mixture  # noqa: E402
from dynatex.analyzer.quilt import learn_quilt, spreading_clip  # noqa: E402
from dynatex.analyzer.tiles import learn_tiles  # noqa: E402
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip  # noqa: E402
from dynatex.benchmark import synthetic_lds_db, time_calls  # noqa: E402
from dynatex.player import open_player  # noqa: E402
from dynatex.tiledb import DatabaseWriter  # noqa: E402


def _write(path: Path, frames: np.ndarray, method: str, model) -> str:
    clip = load_clip(frames)
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
        w.put_method("t", method, model)
    return str(path)


def _lds(folder: Path) -> str:
    return synthetic_lds_db(folder / "lds.h5", 1280, 720)


def _mixture(folder: Path) -> str:
    sea = CLIPS / "water_sea_waves_dyntex.avi"  # as bench_mixture
    waves = load_clip(str(sea)).frames[:100] if sea.exists() else generated_clip(100, 288, 352)
    return _write(folder / "mixture.h5", waves, "mixture", learn_mixture(load_clip(waves)))


def _tiles(folder: Path) -> str:
    tiles = str(folder / "tiles.h5")
    grass = CLIPS / "grass_straw_wind_dyntex.avi"  # as bench_tiles: the README's tiles figures
    clip = load_clip(str(grass)).frames if grass.exists() else generated_clip(250, 288, 352)
    write_tiles_db(tiles, clip, learn_tiles(clip))
    return tiles


def _turnpoints(folder: Path) -> str:
    import cv2

    pend = pendulum_clip(72, 96)[0]
    pend = np.stack([cv2.resize(f, (1280, 720), interpolation=cv2.INTER_LINEAR) for f in pend])
    return _write(folder / "turn.h5", pend, "turnpoints", learn_turnpoints(load_clip(pend)))


def _evolve(folder: Path) -> str:
    spread = spreading_clip(24, 64, 64)
    return _write(folder / "quilt.h5", spread, "quilt", learn_quilt(spread, size=(512, 512), seed=1))


#: (label, database writer, player options) of the benchmarked cases, 1280x720 but mixture and evolve
CASES = [
    ("lds 1280x720", _lds, {"mode": "lds"}),
    ("mixture 352x288", _mixture, {"mode": "mixture"}),
    (
        "tiles 1280x720",
        _tiles,
        {"mode": "tiles", "size": (720, 1280), "tone": "consensus", "controls": {"sigma": 64.0}},
    ),
    ("turnpoints 1280x720", _turnpoints, {"mode": "turnpoints", "playback": "hybrid"}),
    ("evolve 512x512", _evolve, {"mode": "evolve", "jitter": 2.0}),
]


def databases(folder: Path, modes: list[str] | None = None) -> list[tuple[str, str, dict]]:
    """(label, database, player options) of the benchmarked cases whose mode is in ``modes`` (None: all)."""
    return [(label, write(folder), options) for label, write, options in CASES if not modes or options["mode"] in modes]


def bench(db: str, options: dict, frames: int, rounds: int, backend: str = "opencl") -> dict:
    options = dict(options, backend=backend)
    controls = options.pop("controls", {})
    players = {
        f: open_player(db, seed=1, format=f.upper() if f != "rgb+numpy" else "RGB", **options)
        for f in ("rgb", "rgb+numpy", "rgba", "bgra")
    }
    try:
        for p in players.values():
            for name, value in controls.items():
                setattr(p, name, value)
        shape = players["rgb"].shape
        bufs = {f: np.zeros(p.shape, np.uint8) for f, p in players.items()}
        rgba = np.full(shape[:2] + (4,), 255, np.uint8)

        def convert():
            players["rgb+numpy"].next_frame(out=bufs["rgb+numpy"])
            rgba[..., :3] = bufs["rgb+numpy"]

        calls = {
            "rgb": lambda: players["rgb"].next_frame(out=bufs["rgb"]),
            "rgb+numpy": convert,
            "rgba": lambda: players["rgba"].next_frame(out=bufs["rgba"]),
            "bgra": lambda: players["bgra"].next_frame(out=bufs["bgra"]),
        }
        times: dict[str, list] = {f: [] for f in calls}
        for r in range(rounds):
            for f, fn in calls.items():
                times[f].append(
                    time_calls(
                        fn, frames=max(2, frames // rounds), warmup=3 if r == 0 else 1, max_seconds=20.0 / rounds
                    )
                )
        med = {f: float(np.median(np.concatenate(t))) * 1e3 for f, t in times.items()}
        return {
            "backend": players["rgb"].backend,
            "median_ms": med,
            "vs_rgb_numpy": {f: med[f] / med["rgb+numpy"] for f in ("rgba", "bgra")},
            "speed_vs_rgb": {f: med["rgb"] / med[f] for f in ("rgba", "bgra")},
        }
    finally:
        for p in players.values():
            p.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--backend", choices=("opencl", "numpy"), default="opencl")
    ap.add_argument("--modes", nargs="*", help="the cases whose mode is one of these (default: all)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for label, db, options in databases(Path(tmp), args.modes):
            row = {"case": label, **bench(db, options, args.frames, args.rounds, args.backend)}
            rows.append(row)
            if not args.json:
                m, v = row["median_ms"], row["speed_vs_rgb"]
                print(
                    f"{label} ({row['backend']}): rgb {m['rgb']:.3f} ms, rgb+numpy {m['rgb+numpy']:.3f} ms, "
                    f"rgba {m['rgba']:.3f} ms ({v['rgba']:.2f}x rgb speed), "
                    f"bgra {m['bgra']:.3f} ms ({v['bgra']:.2f}x)",
                    flush=True,
                )
    if args.json:
        print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
