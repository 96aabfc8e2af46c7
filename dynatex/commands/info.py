"""``dynatex info DB.h5``: what a tile database holds."""
from __future__ import annotations

import argparse
import json

import numpy as np

from ..tiledb import open_db


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser("info", help="describe a tile database", description="List the textures of a tile "
                       "database, their source and the methods stored for each (validating them).")
    p.add_argument("database")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    return p


def describe(path: str) -> dict:
    """A plain dict describing every texture and method of the database at ``path``."""
    with open_db(path) as db:
        out = {"file": path, "format_version": list(db.version), "textures": {}}
        for tex in db:
            s = tex.source
            entry = {"source": {"filename": s.filename, "sha256": s.sha256, "fps": s.fps,
                                "size": [s.width, s.height], "channels": s.channels, "frames": s.n_frames},
                     "frames_stored": tex.has_frames, "methods": {}}
            for method in tex.methods:
                entry["methods"][method] = _method_info(method, tex.read(method))
            out["textures"][tex.name] = entry
        return out


def _method_info(method: str, model) -> dict:
    info = {k: _plain(v) for k, v in (getattr(model, "info", None) or {}).items()}
    if method == "lds":
        info.update(n=model.n, k=model.k, basis_mb=round(model.basis.nbytes / 2**20, 2))
    if method == "tiles":
        pure = model.ring_class == model.tile_class
        info.update(n_tiles=model.n_tiles, tile_size=f"{model.tile_size[1]}x{model.tile_size[0]}",
                    loop_length=model.loop_length, classes=list(model.class_names),
                    tiles_per_class=[int(len(model.tiles_of(c))) for c in range(model.n_classes)],
                    border_tiles=int((~pure).sum()), loop_start=model.class_loop_start.tolist(),
                    loop_cost=[round(float(v), 4) for v in model.class_loop_cost],
                    toroid_cut_cost=[[round(float(v), 2) for v in row] for row in model.class_toroid_cost],
                    ring_seam_cost=[round(float(v), 2) for v in model.seam_cost],
                    mean_rgb=[[round(float(v), 1) for v in row] for row in model.mean_rgb],
                    tiles_mb=round(model.tiles.nbytes / 2**20, 2))
        info.setdefault("construction", "wang" if model.wang else "ring")
        if model.wang:
            info["wang_edges_left_right_top_bottom"] = model.edges.tolist()
        from ..analyzer.tiles import stationarity_warning
        warning = stationarity_warning(model.info)
        if warning:
            info["warning"] = warning
    return info


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return v


def run(args: argparse.Namespace) -> int:
    d = describe(args.database)
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    print(f"{d['file']}: dynatex tile database v{d['format_version'][0]}.{d['format_version'][1]}, "
          f"{len(d['textures'])} texture(s)")
    for name, t in d["textures"].items():
        s = t["source"]
        print(f"\n[{name}] from {s['filename']} ({s['size'][0]}x{s['size'][1]}x{s['channels']}, "
              f"{s['frames']} frames at {s['fps']:g} fps), frames stored: {'yes' if t['frames_stored'] else 'no'}")
        for method, info in t["methods"].items():
            print(f"  {method}:")
            for key, value in info.items():
                if isinstance(value, float):
                    value = f"{value:.6g}"
                print(f"    {key:24s} {value}")
    return 0
