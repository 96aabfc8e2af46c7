"""Video out end to end: ``dynatex play`` of 1920x1080 tiles to ``.mp4`` (a fresh process, the
whole command timed), the file's size and bitrate, and its PSNR against the frames the player
renders (the same seed, rendered again in this process). Issue 29's floors: 300 frames in at
most 20 s, PSNR at least 35 dB. The command's CPU seconds are printed beside its wall time: on
a shared machine they say what it costs, whatever the load.

    python benchmarks/bench_video_out.py [--frames 300] [--size 1920x1080] [-- EXTRA PLAY ARGS]

Uses the real grass clip when ../shared/data/clips is there (as bench_tiles), else a
generated clip. Any arguments after ``--`` go to ``dynatex play`` (``--crf``, ``--preset``).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_tiles import CLIPS, generated_clip, write_db  # noqa: E402

from dynatex.analyzer import load_clip  # noqa: E402
from dynatex.analyzer.tiles import learn_tiles  # noqa: E402
from dynatex.player import open_player  # noqa: E402


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def _children_cpu() -> float:
    """CPU seconds (user + system) of the finished child processes: the command's own work,
    whatever else loads the machine (its wall time on idle cores is at least this over their number)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("play_args", nargs="*", help="extra arguments of dynatex play (after --)")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    import av

    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "tiles.h5")
        grass = CLIPS / "grass_straw_wind_dyntex.avi"
        clip = load_clip(str(grass)).frames if grass.exists() else generated_clip(250, 288, 352)
        write_db(db, clip, learn_tiles(clip))
        out = os.path.join(tmp, "out.mp4")
        cmd = [sys.executable, "-m", "dynatex", "play", db, "--mode", "tiles", "--size", f"{w}x{h}"]
        cmd += ["--frames", str(args.frames), "--seed", "1", "-o", out, *args.play_args]
        cpu0 = _children_cpu()
        t0 = time.perf_counter()
        # run outside the checkout: from its root, ``-m dynatex`` would import the checkout's
        # dynatex/ whichever interpreter (and installed dynatex) runs it
        subprocess.run(cmd, check=True, stdin=subprocess.DEVNULL, cwd=tmp)
        seconds = time.perf_counter() - t0
        cpu = _children_cpu() - cpu0
        size = os.path.getsize(out)
        with open_player(db, mode="tiles", size=(h, w), seed=1) as p, av.open(out) as video:
            fps = float(video.streams.video[0].average_rate)
            scores = []
            for frame in video.decode(video=0):
                scores.append(psnr(frame.to_ndarray(format="rgb24")[:h, :w], p.next_frame()))
        row = {
            "frames": args.frames,
            "size": f"{w}x{h}",
            "seconds": seconds,
            "fps": args.frames / seconds,
            "cpu_s": cpu,
            "cores": os.cpu_count(),
            "mbytes": size / 1e6,
            "mbit_s": size * 8 / (args.frames / fps) / 1e6,
            "psnr_db_mean": float(np.mean(scores)),
            "psnr_db_min": float(np.min(scores)),
            "decoded": len(scores),
        }
    if args.json:
        print(json.dumps(row))
    else:
        print(
            f"{row['frames']} frames {row['size']} tiles to .mp4 {' '.join(args.play_args)}: {seconds:.1f} s end to "
            f"end ({row['fps']:.1f} fps; {cpu:.1f} s of CPU, {cpu / row['cores']:.1f} s on {row['cores']} idle cores), "
            f"{row['mbytes']:.1f} MB ({row['mbit_s']:.1f} Mbit/s), PSNR "
            f"{row['psnr_db_mean']:.1f} dB mean, {row['psnr_db_min']:.1f} dB min ({row['decoded']} frames)"
        )


if __name__ == "__main__":
    main()
