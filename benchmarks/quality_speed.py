"""Does the LDS speed control scale time? Dominant temporal frequency and energy at several speeds.

    python benchmarks/quality_speed.py [--frames 20000] [--speeds 1,2,0.5,-1] [--clips a.avi,b.avi] [--json]

For each real clip (default: sea, fountain, flag from ``../shared/data/clips``) the default
analysis (``learn_lds(clip)``) is played, after 50 warm-up frames, for ``--frames`` frames at
each speed, same seed (long runs: a slow texture's energy wanders for hundreds of frames).
Per speed:

- ``freq``: the dominant temporal frequency of the output (cycles per frame): the power-weighted
  mean frequency of the Welch temporal power spectrum (Hann segments of 1,024 frames, half
  overlap, each pixel's mean removed, DC left out) summed over 2,000 random pixel channels
  (the same channels give the energies).
  A flat, broadband LDS spectrum has no single peak; its mean frequency scales with time
  exactly as a peak would (a process played ``s`` times faster has the spectrum ``S(f / s) / s``).
  ``peak`` is the spectrum's highest bin, for reference.
- ``freq_ratio``: ``freq`` over ``freq`` at speed 1 (the contract: ``|speed|``, within 15%).
- ``energy``: mean dynamic energy of the output frames (squared deviation from the source's mean
  frame) over the source's; ``energy_vs_1``: over that of speed 1 (the contract: 0.8-1.25,
  the speed edit keeps the model's stationary covariance).

Run with another interpreter (``/work/main/.venv/bin/python benchmarks/quality_speed.py``) to
measure another checkout's player.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.player import open_player
from dynatex.tiledb import DatabaseWriter

NAMES = ("water_sea_waves_dyntex.avi", "fountain_dyntex_6486110.avi", "flag_wind_dyntex_571c110.avi")
SEGMENT = 1024
WARMUP = 50


def temporal_spectrum(sig: np.ndarray, segment: int = SEGMENT) -> np.ndarray:
    """Welch power spectrum ``(segment // 2 + 1,)`` of ``sig`` ``(T, P)``, summed over the P series."""
    sig = sig - sig.mean(axis=0)
    win = np.hanning(segment)[:, None]
    starts = range(0, sig.shape[0] - segment + 1, segment // 2)
    return sum(np.abs(np.fft.rfft(sig[i : i + segment] * win, axis=0)) ** 2 for i in starts).sum(axis=1)


def dominant_frequency(sig: np.ndarray) -> tuple[float, float]:
    """(power-weighted mean frequency, peak frequency) in cycles per frame, DC left out."""
    power = temporal_spectrum(sig)[1:]
    f = np.arange(1, power.size + 1) / SEGMENT
    return float((f * power).sum() / power.sum()), float(f[int(np.argmax(power))])


def play(db: Path, speed: float, frames: int, pix: np.ndarray, mean: np.ndarray, seed: int) -> dict:
    """Sampled pixel series and mean dynamic energy of ``frames`` frames at ``speed``.

    The player runs its own recursion (``advance``); the sampled pixels of each frame are its
    projection (the detail part left out), rounded and saturated to uint8 as the kernel does (checked against rendered
    frames), so long runs cost microseconds a frame instead of a full projection.
    """
    with open_player(db, seed=seed) as p:
        p.advance(WARMUP)
        p.speed = speed
        x = p.advance(frames, record=True)
        model = p.texture.read("lds")
        rows = model.basis[:, pix].astype(np.float64)
        sig = np.clip(np.rint(x @ rows + model.mean[pix]), 0, 255)
        if model.detail is not None:  # the source's per-pixel colour range holds with the detail off too
            sig = np.clip(sig, model.detail.low.reshape(-1)[pix], model.detail.high.reshape(-1)[pix])
        p.detail = 0.0  # the projection's pixels (the detail's clock follows the speed on its own)
        for t in (0, frames // 2, frames - 1):  # the shortcut is what the player draws
            drawn = p.render_state(x[t]).reshape(-1)[pix].astype(np.float64)
            assert np.abs(drawn - sig[t]).max() <= 1, "sampled projection differs from the rendered frame"
    freq, peak = dominant_frequency(sig)
    return {"freq": freq, "peak": peak, "energy_abs": float(np.mean((sig - mean[pix]) ** 2))}


def measure(path: Path, speeds: list[float], frames: int, tmp: str, seed: int = 1) -> dict:
    clip = load_clip(path)
    db = Path(tmp) / f"{path.stem}.h5"
    with DatabaseWriter(db) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "lds", learn_lds(clip, tone="off"))  # levels: the check below rebuilds pixels from the model
    src = clip.frames.reshape(clip.n_frames, -1).astype(np.float64)
    mean = src.mean(axis=0)
    pix = np.random.default_rng(0).choice(src.shape[1], 2000, replace=False)
    src_energy = float(np.mean((src[:, pix] - mean[pix]) ** 2))
    rows = {s: play(db, s, frames, pix, mean, seed) for s in speeds}  # speeds holds 1
    base_freq, base_energy = rows[1.0]["freq"], rows[1.0]["energy_abs"]
    for s, r in rows.items():
        e = r.pop("energy_abs")
        r["energy"] = e / src_energy
        r["freq_ratio"] = r["freq"] / base_freq
        r["energy_vs_1"] = e / base_energy
        r["ok"] = bool((s == 0 or abs(r["freq_ratio"] / abs(s) - 1) <= 0.15) and 0.8 <= r["energy_vs_1"] <= 1.25)
    return {"clip": path.name, "frames": frames, "speeds": {str(s): r for s, r in rows.items()}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=20000)
    ap.add_argument("--speeds", default="1,2,0.5,-1")
    ap.add_argument("--clips", default=",".join(NAMES))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    speeds = [float(s) for s in args.speeds.split(",")]
    if 1.0 not in speeds:
        speeds.insert(0, 1.0)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.clips.split(","):
            path = CLIPS / name
            if not path.exists():
                print(f"skipping {name}: not in {CLIPS}", file=sys.stderr)
                continue
            results.append(measure(path, speeds, args.frames, tmp))
            if not args.json:
                r = results[-1]
                print(f"{r['clip']} ({r['frames']} frames per speed)")
                print("  speed  freq    peak    freq/f1  energy  energy/e1  ok")
                for s, v in r["speeds"].items():
                    print(
                        f"  {float(s):5.2f}  {v['freq']:.4f}  {v['peak']:.4f}  {v['freq_ratio']:7.3f}  "
                        f"{v['energy']:6.3f}  {v['energy_vs_1']:9.3f}  {'yes' if v['ok'] else 'NO'}"
                    )
    if args.json:
        json.dump(results, sys.stdout, indent=2)
        print()
    return 0 if all(v["ok"] for r in results for v in r["speeds"].values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
