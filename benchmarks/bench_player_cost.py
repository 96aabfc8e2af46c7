"""Cost per frame of ``lds`` / ``mixture`` against the same player without the parts issue 27
added: CPU time (player process, OpenCL runtime threads included) and frame rate of
``next_frame`` (look-ahead 1 unless told, detail on) on the database as stored and on scratch
copies without parts, in alternating rounds (medians kept: the machine is shared), so that
every ratio comes from one run.

Variants: ``full`` (as stored); ``plain`` (no ``tone``, ``residual`` or ``gamut`` part: the
projection, and the detail where the model has one, as the player drew before them; the whole
colour set goes too, because a model learned on tone values projects to tone values, and its
colour stage would then work on frames that are no real frames; without the tone part, the mean
is clipped into the levels' range, as a reader wants it: the cost does not depend on its values);
``global`` (no ``gamut/local``:
the clip's colour set alone, on real frames); ``notone`` and ``nores`` on request.

    python benchmarks/bench_player_cost.py DB.h5 [--mode lds] [--lookahead 1] [--frames 24]
        [--rounds 3] [--device 0:0] [--backends numpy,opencl] [--variants full,plain,global]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile

import h5py
import numpy as np
from bench_lookahead import measure

#: the parts each variant leaves out of the lds and mixture models
STRIP = {
    "full": (),
    "plain": ("tone", "residual", "gamut"),
    "global": ("gamut/local",),
    "notone": ("tone",),
    "nores": ("residual",),
}


def without(db: str, folder: str, variant: str) -> str:
    """A scratch copy of ``db`` whose lds and mixture models lack the parts of ``variant``."""
    if not STRIP[variant]:
        return db
    out = os.path.join(folder, f"{variant}.h5")
    shutil.copy(db, out)
    with h5py.File(out, "a") as f:
        for texture in f["textures"].values():
            for method in ("lds", "mixture"):
                for part in STRIP[variant]:
                    if method in texture and part in texture[method]:
                        del texture[method][part]
                        if part == "tone":  # a model on levels has its mean in their range
                            mean = texture[method]["mean"]
                            mean[...] = np.clip(mean[...], 0, 255)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("db")
    ap.add_argument("--mode", default="lds")
    ap.add_argument("--lookahead", type=int, default=1)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--backends", default="numpy,opencl")
    ap.add_argument("--variants", default="full,plain,global")
    args = ap.parse_args()
    variants = args.variants.split(",")
    options = {"lookahead": args.lookahead} if args.lookahead > 1 else {}
    runs: dict[tuple[str, str], list] = {}
    loads = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="dynatex-cost-") as tmp:
        dbs = {v: without(args.db, tmp, v) for v in variants}
        for _ in range(args.rounds):
            for backend in args.backends.split(","):
                for v, db in dbs.items():
                    cpu, fps, _ = measure(db, args.mode, backend, args.device, options, True, args.frames)
                    runs.setdefault((backend, v), []).append((cpu, fps))
            loads.append(os.getloadavg()[0])
    for backend in args.backends.split(","):
        med = {v: np.median(runs[(backend, v)], axis=0) for v in variants}
        row = {"backend": backend, "lookahead": args.lookahead}
        row.update({f"cpu_ms_{v}": round(float(m[0]), 2) for v, m in med.items()})
        row.update({f"fps_{v}": round(float(m[1]), 1) for v, m in med.items()})
        row.update({f"cpu_full/{v}": round(float(med["full"][0] / m[0]), 3) for v, m in med.items() if v != "full"})
        row["load"] = f"{min(loads):.1f}-{max(loads):.1f}"
        print(json.dumps(row))


if __name__ == "__main__":
    main()
