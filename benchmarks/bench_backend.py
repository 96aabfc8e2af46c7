"""``backend="auto"`` against the numpy reference for the projection modes (lds, mixture), per
size and precision: the backend auto chose (the self-test's measured speed decides it, see
``python -m dynatex.player --check``) and auto's frame rate over numpy's. Issue 29's floor:
0.95x or better everywhere.

    python benchmarks/bench_backend.py [--rounds 15] [--frames 8] [--sizes 352x288 1280x720]
        [--first SPEC] [--lookahead K] [--dbs FOLDER] [--json]

Timing: alternating rounds (auto then numpy, numpy then auto, ...), each a block of ``--frames``
frames of one player; the figure is the median of the per-round ratios (numpy's block time over
auto's), with its quartiles, so a load that changes during the run weighs on both alike.
``--first`` (an index ``P:D`` or a name, as ``device=``: "Intel(R) OpenCL" for Intel's CPU
runtime, whose device name PoCL's also holds) puts one device first in the player's order of
preference, as on a machine where it is the only one (a device named with ``device=`` is
OpenCL's by the user's choice, so auto's rule is measured on the device it takes by itself);
``--lookahead`` renders k frames per pass on both players.

lds textures are synthetic (n=50, as bench_lds); mixture is learned from the first 100 frames
of the real sea clip when ../shared/data/clips is there (else a generated clip), at each size
(the frames resized). ``--dbs`` keeps the databases in FOLDER and reuses them.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_formats import _write  # noqa: E402
from bench_tiles import CLIPS, generated_clip  # noqa: E402

from dynatex.analyzer import load_clip  # noqa: E402
from dynatex.analyzer.mixture import learn_mixture  # noqa: E402
from dynatex.benchmark import synthetic_lds_db  # noqa: E402
from dynatex.player import open_player  # noqa: E402


def bench(db: str, mode: str, precision: str, frames: int, rounds: int, lookahead: int) -> dict:
    opts = {"mode": mode, "precision": precision, "seed": 1, "lookahead": lookahead}
    players = {
        "auto": open_player(db, backend="auto", **opts),
        "numpy": open_player(db, backend="numpy", **opts),
    }
    try:
        out = np.empty(players["numpy"].shape, np.uint8)

        def block(p) -> float:
            t = time.perf_counter()
            for _ in range(frames):
                p.next_frame(out=out)
            return time.perf_counter() - t

        for p in players.values():  # warm: a whole pass and more
            for _ in range(max(3, 2 * lookahead)):
                p.next_frame(out=out)
        times: dict[str, list[float]] = {"auto": [], "numpy": []}
        for r in range(rounds):
            order = ("auto", "numpy") if r % 2 == 0 else ("numpy", "auto")
            for b in order:
                times[b].append(block(players[b]))
        ratios = np.array(times["numpy"]) / np.array(times["auto"])
        q1, med, q3 = np.percentile(ratios, [25, 50, 75])
        fps = {b: frames / float(np.median(t)) for b, t in times.items()}
        return {
            "auto_backend": players["auto"].backend,
            "fps": fps,
            "auto_vs_numpy": float(med),
            "quartiles": [float(q1), float(q3)],
        }
    finally:
        for p in players.values():
            p.close()


def first(spec: str) -> None:
    """Put the device ``spec`` names first in the player's order of preference (this process only)."""
    from dynatex.player.opencl import context, devices

    chosen = devices.find_device(devices.devices(), spec, "--first")  # a name matching several: PoCL's
    print(f"auto's device: {chosen.index} {chosen.describe()}", flush=True)
    order = devices.preference_order

    def preference_order(infos):
        return [chosen] + [d for d in order(infos) if d != chosen]

    context.preference_order = preference_order


def databases(folder: Path, sizes: list[str]) -> list[tuple[str, str, str]]:
    """(label, database, mode) of every case, written into ``folder`` unless already there."""
    import cv2

    cases = []
    sea = CLIPS / "water_sea_waves_dyntex.avi"
    waves = None
    for size in sizes:
        w, h = (int(v) for v in size.split("x"))
        lds = folder / f"lds{size}.h5"
        if not lds.exists():
            synthetic_lds_db(lds, w, h)
        cases.append((f"lds {size}", str(lds), "lds"))
    for size in sizes:
        w, h = (int(v) for v in size.split("x"))
        mix = folder / f"mixture{size}.h5"
        if not mix.exists():
            if waves is None:
                waves = load_clip(str(sea)).frames[:100] if sea.exists() else generated_clip(100, 288, 352)
            frames = np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in waves])
            _write(mix, frames, "mixture", learn_mixture(load_clip(frames)))
        cases.append((f"mixture {size}", str(mix), "mixture"))
    return cases


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8, help="frames per block (a round: a block of each)")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--sizes", nargs="*", default=["352x288", "1280x720"])
    ap.add_argument("--first", default=None, help="the device auto takes (default: the first verified, PoCL first)")
    ap.add_argument("--lookahead", type=int, default=1)
    ap.add_argument("--dbs", default=None, help="folder keeping the databases between runs")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.first:
        first(args.first)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.dbs or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for label, db, mode in databases(folder, args.sizes):
            for precision in ("float32", "float16"):
                row = {
                    "case": label,
                    "precision": precision,
                    **bench(db, mode, precision, args.frames, args.rounds, args.lookahead),
                }
                rows.append(row)
                if not args.json:
                    q1, q3 = row["quartiles"]
                    print(
                        f"{label} {precision}: auto ({row['auto_backend']}) {row['fps']['auto']:.0f} fps, numpy "
                        f"{row['fps']['numpy']:.0f} fps -> {row['auto_vs_numpy']:.2f}x (quartiles {q1:.2f}-{q3:.2f})",
                        flush=True,
                    )
    if args.json:
        print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
