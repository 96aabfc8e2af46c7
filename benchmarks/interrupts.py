"""Signals at random moments of ``dynatex analyze``: how each run ends, and what it leaves behind.

Each trial starts ``dynatex analyze CLIP -o db.h5`` on a small generated video, sends SIGINT or
SIGTERM after a random delay and records the exit code, whether stderr reports an interrupt
Python swallowed ("Exception ignored ... KeyboardInterrupt") and what remains in the run's
temporary folder. Run with another interpreter to measure another checkout:
``python benchmarks/interrupts.py --python /work/main/.venv/bin/python``.
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np


def _video(path: str) -> None:
    import cv2

    rng = np.random.default_rng(0)
    out = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 25, (96, 72))
    for _ in range(120):
        out.write(rng.integers(0, 256, (72, 96, 3), dtype=np.uint8))
    out.release()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable, help="interpreter whose dynatex runs")
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--signal", choices=("INT", "TERM"), default="INT")
    parser.add_argument("--max-delay", type=float, default=4.0, help="latest moment of the signal, seconds")
    args = parser.parse_args(argv)
    signum = getattr(signal, f"SIG{args.signal}")
    rng = random.Random(1)
    outcomes: collections.Counter = collections.Counter()
    with tempfile.TemporaryDirectory() as work:
        clip = os.path.join(work, "clip.avi")
        _video(clip)
        for i in range(args.trials):
            scratch = tempfile.mkdtemp(dir=work)
            db = os.path.join(scratch, "db.h5")
            env = dict(os.environ, TMPDIR=scratch)
            cmd = [args.python, "-m", "dynatex", "analyze", clip, "-o", db, "-q", "--methods", "lds,tiles"]
            p = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, cwd=work, env=env)
            time.sleep(rng.uniform(0.2, args.max_delay))
            p.send_signal(signum)
            _, err = p.communicate(timeout=300)
            swallowed = "Exception ignored" in err and "KeyboardInterrupt" in err
            left = sorted(n for n in os.listdir(scratch) if n != "db.h5")
            committed = os.path.exists(db)
            lines = err.strip().splitlines()
            line = " | ".join(lines[-3:]) if len(lines) > 1 else "".join(lines)
            outcomes[(p.returncode, swallowed, committed, bool(left))] += 1
            print(
                f"trial {i + 1}: exit {p.returncode}, swallowed {swallowed}, committed {committed}, "
                f"left {left}, stderr ({len(lines)} lines) {line!r}",
                flush=True,
            )
    print("exit, swallowed, committed, left anything -> trials")
    for key, n in sorted(outcomes.items()):
        print(f"  {key}: {n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
