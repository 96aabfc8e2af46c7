"""Does a state process that stays on the clip's path stop the lds ghosting? (issue 27)

    python benchmarks/lds_path_dynamics.py OUTDIR [--clips flag,sea,grass,fountain] [--sheets]

Per clip, the default lds analysis (``OUTDIR/CLIP.h5``, made when absent) is played by three
state processes through the same player (numpy backend, seed 1), each with the model's detail
part on and off:

- ``linear``: the model's own ``x <- A x + B v``;
- ``kernel``: a Nadaraya-Watson regression over the clip's own training pairs
  ``x_t -> x_{t+1}``: the next state is the kernel-weighted mean of the successors of the
  training states near the current one (Gaussian kernel, bandwidth ``--bandwidth`` times the
  median distance of a training state to its nearest other one), plus Gaussian noise with the
  regression's leave-one-out residual covariance;
- ``replay``: the clip's own states in order, the floor any state process can reach (all ``T`` of
  them from the first, not 300 after 50: the clip has no more).

Figures on 300 frames after 50: ``local_novelty`` (the ghosting figure; good <= 1.15, bad >
1.35), the spectrum distance and frame step ratio; over 3,000 state steps after 200, the state
energy over the training states', the share of steps within half a training step of a training
state and the longest run that follows the training states one by one. ``--sheets`` writes the
source beside each process's output after 1,000 frames and a strip of 8 consecutive frames of
each process at 1:1.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
from _clips import CLIPS

CASES = {
    "flag": "flag_wind_dyntex_571c110.avi",
    "sea": "water_sea_waves_dyntex.avi",
    "grass": "grass_straw_wind_dyntex.avi",
    "fountain": "fountain_dyntex_6486110.avi",
}


def _sq(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.maximum((a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2 * a @ b.T, 0.0)


class KernelProcess:
    """Nadaraya-Watson dynamics on the training states ``(n, T)``."""

    def __init__(self, states: np.ndarray, bandwidth: float) -> None:
        x = states.T
        self.x0, self.x1 = x[:-1], x[1:]
        d2 = _sq(self.x0, self.x0)
        np.fill_diagonal(d2, np.inf)
        # a clip with repeated frames has training states at distance 0: keep the kernel finite
        self.h2 = max(2 * (bandwidth * float(np.median(np.sqrt(d2.min(1))))) ** 2, 1e-12 * float(d2[d2 < np.inf].max()))
        w = np.exp(-(d2 - d2.min(1, keepdims=True)) / self.h2)
        w /= w.sum(1, keepdims=True)
        resid = self.x1 - w @ self.x1
        lam, u = np.linalg.eigh(resid.T @ resid / len(resid))
        self.noise = u * np.sqrt(np.clip(lam, 0, None))

    def step(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        d2 = ((self.x0 - x) ** 2).sum(1)
        w = np.exp(-(d2 - d2.min()) / self.h2)
        return (w / w.sum()) @ self.x1 + self.noise @ rng.standard_normal(len(x))


def path_figures(traj: np.ndarray, states: np.ndarray) -> tuple[float, int]:
    """Share of ``traj`` (rows) within half a median training step of a training state, and the
    longest run of such steps that follows the training states one by one."""
    x = states.T
    step = float(np.median(np.sqrt((np.diff(x, axis=0) ** 2).sum(1))))
    d2 = _sq(traj, x)
    j, close = d2.argmin(1), np.sqrt(d2.min(1)) < 0.5 * step
    run = best = 0
    for i in range(1, len(j)):
        run = run + 1 if close[i] and close[i - 1] and j[i] == j[i - 1] + 1 else 0
        best = max(best, run)
    return float(close.mean()), best + 1 if close.any() else 0


def play(db: Path, process: str, states: np.ndarray, bandwidth: float, detail: float, count: int) -> np.ndarray:
    from dynatex.player.modes.lds import LDSPlayer

    with LDSPlayer(db, seed=1, backend="numpy") as p:
        p.detail = detail
        if process == "kernel":
            kp = KernelProcess(states, bandwidth)

            def step() -> None:
                p._x = kp.step(p._x, p._rng)

            p._step = step
        elif process == "replay":
            p._x = states[:, 0].copy()
            clock = [0]

            def step() -> None:
                clock[0] += 1
                p._x = states[:, clock[0] % states.shape[1]].copy()

            p._step = step
        return np.stack([p.next_frame() for _ in range(count)])


def trajectory(process: str, model, bandwidth: float, steps: int = 3000) -> np.ndarray:
    rng = np.random.default_rng(1)
    x, out = model.states[:, 0].copy(), []
    kp = KernelProcess(model.states, bandwidth) if process == "kernel" else None
    for _ in range(steps):
        x = kp.step(x, rng) if kp else model.A @ x + model.B @ rng.standard_normal(model.k)
        out.append(x)
    return np.array(out)[200:]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("outdir")
    ap.add_argument("--clips", default=",".join(CASES))
    ap.add_argument("--bandwidth", type=float, default=0.5)
    ap.add_argument("--sheets", action="store_true")
    args = ap.parse_args()

    from dynatex.analyzer.metrics import evaluate, local_novelty
    from dynatex.analyzer.sheet import contact_sheet
    from dynatex.analyzer.video import load_clip_path
    from dynatex.tiledb import open_db

    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    for case in args.clips.split(","):
        clip = CLIPS / CASES[case]
        if not clip.exists():
            print(f"skipping {case}: {clip} is absent", file=sys.stderr)
            continue
        db = out / f"{case}.h5"
        if not db.exists():
            cmd = [sys.executable, "-m", "dynatex", "analyze", str(clip), "-o", str(db), "--methods", "lds", "-q"]
            subprocess.run(cmd, check=True)
        src = load_clip_path(str(clip)).frames
        with open_db(db) as d:
            model = d.texture().read("lds")
        train = float((model.states**2).sum(0).mean())
        for process in ("linear", "kernel", "replay"):
            if process == "replay":
                energy, near, run = 1.0, 1.0, model.states.shape[1]
            else:
                traj = trajectory(process, model, args.bandwidth)
                energy = float((traj**2).sum(1).mean()) / train
                near, run = path_figures(traj, model.states)
            for detail in (1.0, 0.0):
                count = model.states.shape[1] if process == "replay" else 350
                frames = play(db, process, model.states, args.bandwidth, detail, count)
                frames = frames if process == "replay" else frames[50:]
                rep = evaluate(frames, src)
                print(
                    f"{case:9s} {process:7s} detail {detail:.0f}: local novelty {local_novelty(frames, src):.2f}  "
                    f"spectrum {rep['spectrum_distance_db']:.2f} dB  step {rep['frame_step_ratio']:.2f}  "
                    f"state energy {energy:.2f}  near source {near:.3f}  longest run {run}",
                    flush=True,
                )
            if args.sheets and process != "replay":
                late = play(db, process, model.states, args.bandwidth, 1.0, 1008)[-8:]
                title = f"{case} {process} at 1000"
                contact_sheet(src, late[:1], out / f"{case}_{process}_sheet.png", rows=1, title=title)
                if case == "flag":
                    _strip(late, out / f"{case}_{process}_strip.png")
    return 0


def _strip(frames: np.ndarray, path: Path) -> None:
    """Eight consecutive frames at 1:1, two rows of four."""
    from PIL import Image

    rows = [np.concatenate(list(frames[i : i + 4]), axis=1) for i in (0, 4)]
    Image.fromarray(np.concatenate(rows, axis=0)).save(path)


if __name__ == "__main__":
    raise SystemExit(main())
