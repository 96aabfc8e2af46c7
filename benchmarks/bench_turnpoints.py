"""Turn-point mode benchmark: playback frame rate, analysis time, and the playback comparison.

    python benchmarks/bench_turnpoints.py [--frames 300] [--json] [--no-compare]

Player: a 48-frame 1280x720 clip (a rendered pendulum, upscaled), frames in memory on the
device, ``next_frame(out=...)`` end to end at speed 1 (copies, a blend at each jump's
crossfade) and at speed 0.5 (every frame a blend), OpenCL and the numpy reference, against
the copy-bandwidth roofline measured in the same run. Floors: >= 1,000 frames/s at 1280x720.
Analysis: 300 frames at 640x352 (a rendered pendulum), floor <= 10 s.
Comparison: turn points only, transitions only and hybrid playback of the real pendulum and
candle-flame clips (when ../shared/data/clips is there) with the quality metrics.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip
from dynatex.analyzer.metrics import frame_step_ratio, index_coverage, spectrum_distance, temporal_discontinuity
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
from dynatex.benchmark import copy_bandwidth, summarize, time_calls
from dynatex.player.modes.turnpoints import PLAYBACKS, TurnPointPlayer
from dynatex.tiledb import DatabaseWriter

COMPARE = ("pendulum_clock_schoedl.mov", "small_64px/fire_dyntex_64px.avi")


def _resize(frames: np.ndarray, h: int, w: int) -> np.ndarray:
    import cv2

    return np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_LINEAR) for f in frames])


def _write_db(path: str, frames: np.ndarray, **kwargs) -> float:
    clip = load_clip(frames)
    t = time.perf_counter()
    model = learn_turnpoints(clip, **kwargs)
    dt = time.perf_counter() - t
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
        w.put_method("t", "turnpoints", model)
    return dt


def bench_player(folder: str, frames: int, bandwidth: float) -> dict:
    path = os.path.join(folder, "hd.h5")
    _write_db(path, _resize(pendulum_clip(48, 96)[0], 720, 1280))
    out: dict = {"size": "1280x720", "stored_frames": 48}
    for speed in (1.0, 0.5):
        row: dict = {}
        for backend in ("opencl", "numpy"):
            with TurnPointPlayer(path, backend=backend, seed=1) as p:
                p.speed = speed
                buf = np.empty(p.shape, np.uint8)
                n = frames if backend == "opencl" else max(20, frames // 3)
                row[backend] = summarize(time_calls(lambda p=p, buf=buf: p.next_frame(out=buf), frames=n))
                out["memory_mb"] = p.memory_bytes / 2**20 if backend == "opencl" else out.get("memory_mb")
                out["bytes_per_frame"] = p.bytes_per_frame
        # speed 1: one stored frame read and the output written; speed 0.5: two frames read,
        # the blend written to the device buffer, then read and written again by the copy out.
        moved = out["bytes_per_frame"] if speed == 1.0 else out["bytes_per_frame"] * 2
        roof_ms = moved / (bandwidth * 1e9) * 1e3
        row["roofline_ms"] = roof_ms
        row["roofline_fraction"] = roof_ms / row["opencl"]["median_ms"]
        row["speedup_vs_numpy"] = row["numpy"]["median_ms"] / row["opencl"]["median_ms"]
        out[f"speed_{speed:g}"] = row
    return out


def bench_analysis(folder: str, repeats: int = 3) -> dict:
    frames = _resize(pendulum_clip(300, 88)[0], 352, 640)
    times = [_write_db(os.path.join(folder, "a.h5"), frames) for _ in range(repeats)]
    return {"frames": 300, "size": "640x352", "median_s": float(np.median(times)), "max_s": float(np.max(times))}


def play_and_measure(
    path: str,
    source: np.ndarray,
    playback: str,
    *,
    frames: int = 10000,
    crossfade: int = 4,
    seed: int = 1,
    keep: int = 300,
) -> dict:
    """Play ``frames`` frames; measure coverage, events and their frame differences, and the
    likeness of the first ``keep`` output frames to the source."""
    with TurnPointPlayer(path, backend="numpy", playback=playback, seed=seed) as p:
        p.crossfade = crossfade
        prev = p.next_frame()
        cur = np.empty_like(prev)
        idx, ev, pairs, kept = [p.source_index], [p.last_event], [], [prev.copy()]
        for _ in range(frames - 1):
            p.next_frame(cur)
            idx.append(p.source_index)
            ev.append(p.last_event)
            if p.last_event:
                pairs.append(np.stack([prev, cur]))
            if len(kept) < keep:
                kept.append(cur.copy())
            prev, cur = cur, prev
        dead = p.dead_ends
    ratios = [
        temporal_discontinuity(
            np.concatenate(pairs[b : b + 256]), list(range(1, 2 * len(pairs[b : b + 256]), 2)), source=source
        )
        for b in range(0, len(pairs), 256)
    ]
    r = np.concatenate(ratios) if ratios else np.zeros(0)
    ev_arr = np.array(ev)
    out = np.stack(kept)
    return {
        "coverage": index_coverage(np.array(idx), source.shape[0]),
        "dead_ends": dead,
        "turns": int(np.count_nonzero(ev_arr & 1)),
        "jumps": int(np.count_nonzero(ev_arr & 2)),
        "event_ratio_mean": float(r.mean()) if r.size else None,
        "event_ratio_max": float(r.max()) if r.size else None,
        "step_ratio": frame_step_ratio(out, source),
        "spectrum_db": spectrum_distance(out, source),
    }


def compare(folder: str, frames: int = 10000) -> dict:
    result = {}
    for name in COMPARE:
        if not (CLIPS / name).exists():
            continue
        clip = load_clip(CLIPS / name)
        path = os.path.join(folder, "cmp.h5")
        _write_db(path, clip.frames)
        rows = {}
        for playback in PLAYBACKS:
            rows[playback] = play_and_measure(path, clip.frames, playback, frames=frames)
            if playback != "turns":
                raw = play_and_measure(path, clip.frames, playback, frames=frames, crossfade=0, keep=64)
                rows[playback]["event_ratio_mean_no_crossfade"] = raw["event_ratio_mean"]
        result[name] = rows
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300, help="timed frames per player run")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-compare", action="store_true", help="skip the playback comparison on real clips")
    args = ap.parse_args()
    bw = copy_bandwidth(mbytes=128, repeats=3)
    with tempfile.TemporaryDirectory() as folder:
        report = {
            "bandwidth": bw,
            "player": bench_player(folder, args.frames, bw["gbs"]),
            "analysis": bench_analysis(folder),
        }
        if not args.no_compare:
            report["compare"] = compare(folder)
    if args.json:
        json.dump(report, sys.stdout, indent=2, default=float)
        print()
        return 0
    p = report["player"]
    print(
        f"copy bandwidth {bw['gbs']:.1f} GB/s; frames on the device: {p['memory_mb']:.0f} MB "
        f"({p['stored_frames']} frames {p['size']})"
    )
    for key in ("speed_1", "speed_0.5"):
        r = p[key]
        print(
            f"  {key}: OpenCL {r['opencl']['fps']:.0f} fps (median {r['opencl']['median_ms']:.3f} ms, "
            f"p99 {r['opencl']['p99_ms']:.3f} ms, {r['roofline_fraction']:.2f} of roofline); "
            f"numpy {r['numpy']['fps']:.0f} fps -> {r['speedup_vs_numpy']:.2f}x  [floor 1000 fps]"
        )
    a = report["analysis"]
    print(
        f"analysis of {a['frames']} frames {a['size']}: median {a['median_s']:.2f} s, max {a['max_s']:.2f} s "
        f"[floor 10 s]"
    )
    for name, rows in report.get("compare", {}).items():
        print(f"\n{name} (10,000 frames, seed 1)")
        print(
            "| playback | coverage | turns | jumps | event diff / median step (crossfade 4) | max | "
            "without crossfade | step ratio | spectrum dist (dB) | dead ends |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|")
        for pb, r in rows.items():
            nc = r.get("event_ratio_mean_no_crossfade")
            print(
                f"| {pb} | {r['coverage']:.1%} | {r['turns']} | {r['jumps']} | {r['event_ratio_mean']:.2f} | "
                f"{r['event_ratio_max']:.2f} | {'-' if nc is None else f'{nc:.2f}'} | {r['step_ratio']:.2f} | "
                f"{r['spectrum_db']:.2f} | {r['dead_ends']} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
