"""``dynatex info DB.h5``: what a tile database holds."""

from __future__ import annotations

import argparse
import json

from ..cli import printable
from ..tiledb import open_db


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "info",
        help="describe a tile database",
        description="List the textures of a tile "
        "database, their source and the methods stored for each (validating them).",
    )
    p.add_argument("database")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    return p


def describe(path: str) -> dict:
    """A plain dict describing every texture and method of the database at ``path`` (each
    method by its model's ``describe()``)."""
    with open_db(path) as db:
        out = {"file": path, "format_version": list(db.version), "textures": {}}
        for tex in db:
            s = tex.source
            entry = {
                "source": {
                    "filename": s.filename,
                    "sha256": s.sha256,
                    "fps": s.fps,
                    "size": [s.width, s.height],
                    "channels": s.channels,
                    "frames": s.n_frames,
                },
                "frames_stored": tex.has_frames,
                "methods": {},
            }
            for method in tex.methods:
                entry["methods"][method] = tex.read(method).describe()
            out["textures"][tex.name] = entry
        return out


def run(args: argparse.Namespace) -> int:
    d = describe(args.database)
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    print(
        f"{printable(d['file'])}: dynatex tile database v{d['format_version'][0]}.{d['format_version'][1]}, "
        f"{len(d['textures'])} texture(s)"
    )
    for name, t in d["textures"].items():
        s = t["source"]
        print(
            f"\n[{printable(name)}] from {printable(s['filename'])} ({s['size'][0]}x{s['size'][1]}x{s['channels']}, "
            f"{s['frames']} frames at {s['fps']:g} fps), frames stored: {'yes' if t['frames_stored'] else 'no'}"
        )
        for method, info in t["methods"].items():
            print(f"  {method}:")
            for key, value in info.items():
                if isinstance(value, float):
                    value = f"{value:.6g}"
                print(f"    {printable(key):24s} {printable(value)}")
    return 0
