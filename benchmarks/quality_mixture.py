"""Issue 7's quality figures for the subspace-mixture texture, on real clips.

    python benchmarks/quality_mixture.py [--frames 20000] [--json]

1. Reconstruction error (relative squared error of the mean-subtracted clip) of the
   mixture (S components of dimension d) against a single PCA of the same per-frame
   dimension d, and, for reference, of S (d + 1) - 1 (the stacked basis's size: a single
   PCA of that size is the optimal affine subspace, so no mixture can beat it on the
   training frames).
2. Long-run synthesis: ``--frames`` global coordinates from the mixture player with its
   switching dynamics (format 1.6) and, as analysed before them, the AR process on the global
   coordinates (draws = 16, its default, and 1 = the plain AR process), and states from the plain LDS of the same
   clip (``learn_lds(n=50)``, ``LDSPlayer.advance``): distance of each global coordinate to
   the nearest training coordinate, distance of each synthesized frame to the nearest
   training frame (relative to the RMS training frame), and energy ratio against the source
   (overall and the extremes of 1000-frame block means) and, in parentheses, against the
   model's own reconstruction of the clip (a model holding a fraction of the clip's energy
   cannot synthesize more without leaving its manifold). Frame energies and distances are
   computed exactly from the coefficients (frames are linear in them); a few frames are
   also rendered with OpenCL to check.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from _clips import CLIPS

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.player.modes.lds import LDSPlayer
from dynatex.player.modes.mixture import MixturePlayer, nearest_distance
from dynatex.tiledb import DatabaseWriter

NAMES = (
    "water_sea_waves_dyntex.avi",
    "flag_wind_dyntex_571c110.avi",
    "fountain_dyntex_6486110.avi",
    "grass_straw_wind_dyntex.avi",
)


def _blocks(e: np.ndarray, size: int = 1000) -> tuple[float, float]:
    m = e[: e.size // size * size].reshape(-1, size).mean(axis=1)
    return float(m.min()), float(m.max())


def evaluate(path: Path, frames: int, tmp: str) -> dict:
    clip = load_clip(path)
    t = clip.n_frames
    m = learn_mixture(clip)
    s, d = m.components, m.dim
    sv2 = m.singular_values**2
    total = m.info["total_energy"]
    big = s * (d + 1) - 1
    row = {
        "clip": path.name,
        "frames": t,
        "S": s,
        "d": d,
        "D": m.global_dim,
        "p": m.order,
        "mixture": m.info["recon_error"],
        "mixture_hard": m.info["recon_error_hard"],
        "pca_d": float(1 - sv2[:d].sum() / total),
        "pca_stacked": float(1 - sv2[:big].sum() / total),
        "stacked_dim": big,
    }
    lds = learn_lds(clip, n=50)
    db = Path(tmp) / f"{path.stem}.h5"
    with DatabaseWriter(db) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "mixture", m)
        w.put_method("t", "lds", lds)
        w.put_texture("ar", clip.source_info())  # the same model as analysed before format 1.6
        w.put_method("ar", "mixture", dataclasses.replace(m, switching=None))
    yc = clip.frames.reshape(t, -1).astype(np.float64) - m.mean
    ynorm = (yc**2).sum(axis=1)
    src = float(ynorm.mean())
    scale = np.sqrt(src)
    basis = m.stacked_basis.astype(np.float64)
    gram = basis @ basis.T
    sy = basis @ yc.T

    def frame_stats(u):
        e = np.einsum("ni,ij,nj->n", u, gram, u)
        d2 = e[:, None] - 2 * u @ sy + ynorm[None]
        return np.sqrt(np.maximum(d2.min(axis=1), 0)) / scale, e / src

    g0 = m.global_coords
    d2 = ((g0[:, None] - g0[None]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    loo = np.sqrt(d2.min(axis=1))
    yd = ynorm[:, None] - 2 * yc @ yc.T + ynorm[None]
    np.fill_diagonal(yd, np.inf)
    from dynatex.analyzer.mixture import coefficient_matrix

    row["mix_own"] = float(frame_stats(coefficient_matrix(m.responsibilities, m.local_coords))[1].mean())
    row["lds_own"] = float(lds.info["energy_captured"])
    row["train_frame_nn"] = float(np.median(np.sqrt(np.maximum(yd.min(axis=1), 0)))) / scale
    row["train_coord_nn_median"], row["train_coord_nn_max"] = float(np.median(loo)), float(loo.max())
    row["train_coord_rms"] = float(np.sqrt((g0**2).sum(axis=1).mean()))
    for name, texture, draws in (("switching", "t", 1), ("mix16", "ar", 16), ("mix1", "ar", 1)):
        with MixturePlayer(db, texture, backend="numpy", seed=0, draws=draws) as p:
            if p.switching is not None:
                u = p.advance(frames, record=True)  # the coefficients themselves
                g = u @ m.coord_map
            else:
                g = p.advance(frames, record=True)
                u = p.decoder.coefficients(g)
        gd = nearest_distance(g0, g)
        fd, e = frame_stats(u)
        row[name] = {
            "coord_dist_median": float(np.median(gd)),
            "coord_dist_p99": float(np.percentile(gd, 99)),
            "coord_dist_max": float(gd.max()),
            "frame_dist_median": float(np.median(fd)),
            "frame_dist_max": float(fd.max()),
            "energy": float(e.mean()),
            "energy_blocks": _blocks(e),
            "finite": bool(np.isfinite(g).all()),
        }
    with MixturePlayer(db, seed=0) as p:  # OpenCL: rendered frames carry the predicted energy
        p.advance(frames - 1)
        v = p.advance(1, record=True)  # the next frame's vector
        u = v if p.switching is not None else p.decoder.coefficients(v)
        f = p.next_frame().reshape(-1).astype(np.float64) - m.mean
        row["rendered_energy_check"] = (float((f**2).sum() / src), float(frame_stats(u)[1][0]))
    with LDSPlayer(db, backend="numpy", seed=0) as p:
        x = p.advance(frames, record=True)
    lb = lds.basis.astype(np.float64)
    e = (x**2).sum(axis=1)  # orthonormal basis
    d2 = e[:, None] - 2 * x @ (lb @ yc.T) + ynorm[None]
    fd = np.sqrt(np.maximum(d2.min(axis=1), 0)) / scale
    row["lds"] = {
        "frame_dist_median": float(np.median(fd)),
        "frame_dist_max": float(fd.max()),
        "energy": float(e.mean() / src),
        "energy_blocks": tuple(v / src for v in _blocks(e)),
        "finite": bool(np.isfinite(x).all()),
    }
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=20000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if not CLIPS.is_dir():
        print(f"real clips not available: {CLIPS} does not exist", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="dynatex-quality-") as tmp:
        rows = [evaluate(CLIPS / n, args.frames, tmp) for n in NAMES if (CLIPS / n).exists()]
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
        return 0
    print("| clip | S x d | mixture (soft) | mixture (hard) | PCA, d | PCA, S(d+1)-1 |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['clip']} | {r['S']} x {r['d']} | {r['mixture']:.4f} | {r['mixture_hard']:.4f} | "
            f"{r['pca_d']:.4f} | {r['pca_stacked']:.4f} ({r['stacked_dim']}) |"
        )
    print()
    print(
        f"{args.frames} synthesized frames. coord: distance of g to the nearest training g "
        "(median / p99 / max); frame: distance to the nearest training frame / RMS frame (median / max); "
        "energy: mean ratio to the source [min, max of 1000-frame blocks]"
    )
    print(
        "| clip | train coord NN (med/max) | switching coord | frame | energy | global AR draws=16 coord | frame "
        "| energy | draws=1 coord | frame | energy | LDS n=50 frame | energy | training frame NN |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        a, b, c, w = r["mix16"], r["mix1"], r["lds"], r["switching"]
        print(
            f"| {r['clip']} | {r['train_coord_nn_median']:.2f} / {r['train_coord_nn_max']:.2f} "
            f"| {w['coord_dist_median']:.2f} / {w['coord_dist_p99']:.2f} / {w['coord_dist_max']:.2f} "
            f"| {w['frame_dist_median']:.2f} / {w['frame_dist_max']:.2f} "
            f"| {w['energy']:.2f} ({w['energy'] / r['mix_own']:.2f}) "
            f"[{w['energy_blocks'][0]:.2f}, {w['energy_blocks'][1]:.2f}] "
            f"| {a['coord_dist_median']:.2f} / {a['coord_dist_p99']:.2f} / {a['coord_dist_max']:.2f} "
            f"| {a['frame_dist_median']:.2f} / {a['frame_dist_max']:.2f} "
            f"| {a['energy']:.2f} ({a['energy'] / r['mix_own']:.2f}) "
            f"[{a['energy_blocks'][0]:.2f}, {a['energy_blocks'][1]:.2f}] "
            f"| {b['coord_dist_median']:.2f} / {b['coord_dist_p99']:.2f} / {b['coord_dist_max']:.2f} "
            f"| {b['frame_dist_median']:.2f} / {b['frame_dist_max']:.2f} "
            f"| {b['energy']:.2f} ({b['energy'] / r['mix_own']:.2f}) "
            f"[{b['energy_blocks'][0]:.2f}, {b['energy_blocks'][1]:.2f}] "
            f"| {c['frame_dist_median']:.2f} / {c['frame_dist_max']:.2f} "
            f"| {c['energy']:.2f} ({c['energy'] / r['lds_own']:.2f}) "
            f"[{c['energy_blocks'][0]:.2f}, {c['energy_blocks'][1]:.2f}] "
            f"| {r['train_frame_nn']:.2f} |"
        )
    for r in rows:
        print(
            f"{r['clip']}: rendered-frame energy {r['rendered_energy_check'][0]:.3f} vs from coefficients "
            f"{r['rendered_energy_check'][1]:.3f}; AR order {r['p']}; all finite: "
            f"{r['switching']['finite'] and r['mix16']['finite'] and r['mix1']['finite'] and r['lds']['finite']}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
