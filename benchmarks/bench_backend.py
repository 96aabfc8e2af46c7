"""``backend="auto"`` against the numpy reference for the projection modes (lds, mixture), per
size and precision: the backend auto chose (the self-test's measured speed decides it, see
``python -m dynatex.player --check``) and auto's frame rate over numpy's, timed in alternating
rounds of one run. Issue 29's floor: 0.95x or better everywhere.

    python benchmarks/bench_backend.py [--frames 60] [--rounds 3] [--sizes 352x288 1280x720] [--json]

lds textures are synthetic (n=50, as bench_lds); mixture is learned from the first 100 frames
of the real sea clip when ../shared/data/clips is there (else a generated clip), at 352x288.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_formats import _write  # noqa: E402
from bench_tiles import CLIPS, generated_clip  # noqa: E402

from dynatex.analyzer import load_clip  # noqa: E402
from dynatex.analyzer.mixture import learn_mixture  # noqa: E402
from dynatex.benchmark import synthetic_lds_db, time_calls  # noqa: E402
from dynatex.player import open_player  # noqa: E402


def bench(db: str, mode: str, precision: str, frames: int, rounds: int) -> dict:
    players = {b: open_player(db, mode=mode, backend=b, precision=precision, seed=1) for b in ("auto", "numpy")}
    try:
        out = np.empty(players["numpy"].shape, np.uint8)
        times: dict[str, list] = {b: [] for b in players}
        for r in range(rounds):
            for b, p in players.items():
                times[b].append(time_calls(lambda p=p: p.next_frame(out=out), frames=frames, warmup=3 if r == 0 else 1))
        fps = {b: 1.0 / float(np.median(np.concatenate(t))) for b, t in times.items()}
        return {"auto_backend": players["auto"].backend, "fps": fps, "auto_vs_numpy": fps["auto"] / fps["numpy"]}
    finally:
        for p in players.values():
            p.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--sizes", nargs="*", default=["352x288", "1280x720"])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = []
        for size in args.sizes:
            w, h = (int(v) for v in size.split("x"))
            cases.append((f"lds {size}", synthetic_lds_db(Path(tmp) / f"lds{size}.h5", w, h), "lds"))
        sea = CLIPS / "water_sea_waves_dyntex.avi"
        waves = load_clip(str(sea)).frames[:100] if sea.exists() else generated_clip(100, 288, 352)
        mixture = _write(Path(tmp) / "mixture.h5", waves, "mixture", learn_mixture(load_clip(waves)))
        cases.append((f"mixture {waves.shape[2]}x{waves.shape[1]}", mixture, "mixture"))
        for label, db, mode in cases:
            for precision in ("float32", "float16"):
                row = {"case": label, "precision": precision, **bench(db, mode, precision, args.frames, args.rounds)}
                rows.append(row)
                if not args.json:
                    print(
                        f"{label} {precision}: auto ({row['auto_backend']}) {row['fps']['auto']:.0f} fps, numpy "
                        f"{row['fps']['numpy']:.0f} fps -> {row['auto_vs_numpy']:.2f}x",
                        flush=True,
                    )
    if args.json:
        print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
