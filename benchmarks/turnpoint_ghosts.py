"""Double images at turn-point jumps: the measure, the jumps taken and the coverage, per clip.

For every clip given (default: every clip in ``../shared/data/clips``), analyse it with the
``turnpoints`` method (the CLI, so the installed version's defaults apply), play ``--frames``
output frames in hybrid playback and report:

- ``level``: the source's own double-image level (:func:`double_image_level`, 90th percentile);
- ``p99`` and ``max``: :func:`double_image` of the output frames, and ``over``, the share of
  output frames above the level;
- ``trans``: transitions the database holds, ``warped`` those with a motion-compensated
  crossfade; ``jumps``: jumps taken per 100 output frames
  and ``cover``, the share of the source's frames shown, both over a ``--walk`` of 5000 frames.

Run it with another installation's Python to measure that version (the measure itself is
loaded from this checkout when the other version lacks it)::

    python benchmarks/turnpoint_ghosts.py --frames 300
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import os
import subprocess
import sys
import tempfile

import numpy as np
from _clips import CLIPS

from dynatex.analyzer.metrics import index_coverage
from dynatex.player import open_player

HERE = os.path.dirname(os.path.abspath(__file__))
#: analysis options for clips with fewer than two turn points at the defaults (rows marked *)
LOOSE = ["--tp-min-symmetry", "0.05", "--tp-r", "2"]


def _measures():
    try:
        from dynatex.analyzer.metrics import double_image, double_image_level
    except ImportError:  # an older installation: this checkout's measure, on that package
        path = os.path.join(HERE, "..", "analyzer", "metrics", "__init__.py")
        spec = importlib.util.spec_from_file_location(
            "dynatex.analyzer._ghost_metrics", path, submodule_search_locations=[os.path.dirname(path)]
        )
        mod = sys.modules[spec.name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        double_image, double_image_level = mod.double_image, mod.double_image_level
    return double_image, double_image_level


def measure(clip: str, frames: int, tmp: str, seed: int, walk: int, extra_args: tuple = ()) -> dict:
    double_image, double_image_level = _measures()
    db = os.path.join(tmp, os.path.basename(clip) + ".h5")
    name = os.path.basename(clip)
    for extra in ([], LOOSE):  # clips with too few turn points at the defaults: looser turn points
        cmd = [
            sys.executable,
            "-m",
            "dynatex",
            "analyze",
            clip,
            "-o",
            db,
            "--methods",
            "turnpoints",
            *extra_args,
            *extra,
        ]
        r = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
        if not r.returncode:
            name += "*" if extra else ""
            break
    else:
        return {"clip": name, "error": (r.stderr.strip().splitlines() or ["?"])[-1]}
    with open_player(db, mode="turnpoints", seed=seed, backend="numpy") as p:
        source = p.texture.frames().read()
        ratios, idx, jumps = [], [], 0
        done = 0
        while done < frames:
            n = min(50, frames - done)
            chunk = np.stack([p.next_frame() for _ in range(n)])
            ratios.append(double_image(chunk, source))
            done += n
        p.frame_index = 0
        n_trans = int(p.model.src.size)
        n_warped = int(p.model.info.get("n_warped", 0))
    # the walk again (same seed, ``walk`` frames) for the indices and events, without rendering
    with open_player(db, mode="turnpoints", seed=seed, backend="numpy") as p:
        idx, ev = p.advance(walk)
        jumps = int(np.count_nonzero(ev & 2))
    ratios = np.concatenate(ratios)
    level = double_image_level(source)
    return {
        "clip": name,
        "level": level,
        "p99": float(np.quantile(ratios, 0.99)),
        "max": float(ratios.max()),
        "over": float(np.mean(ratios > level)),
        "trans": n_trans,
        "warped": n_warped,
        "jumps": 100.0 * jumps / walk,
        "cover": index_coverage(idx, len(source)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clips", nargs="*")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--walk", type=int, default=5000, help="frames of the walk counted for jumps and coverage")
    ap.add_argument("--analyze", default="", help="extra analysis options, e.g. '--tp-warp off'")
    args = ap.parse_args()
    found = glob.glob(os.path.join(CLIPS, "**", "*"), recursive=True)
    clips = args.clips or sorted(f for f in found if f.endswith((".avi", ".mp4", ".mov", ".gif")))
    print(
        f"{'clip':34} {'level':>6} {'p99':>6} {'max':>6} {'over':>6} {'trans':>5} {'warped':>6} "
        f"{'jumps%':>6} {'cover':>6}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for clip in clips:
            m = measure(clip, args.frames, tmp, args.seed, max(args.walk, args.frames), tuple(args.analyze.split()))
            if "error" in m:
                print(f"{m['clip']:34} not analysed: {m['error']}")
                continue
            print(
                f"{m['clip']:34} {m['level']:6.2f} {m['p99']:6.2f} {m['max']:6.2f} {m['over']:6.3f} "
                f"{m['trans']:5d} {m['warped']:6d} {m['jumps']:6.2f} {m['cover']:6.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
