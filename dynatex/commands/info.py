"""``dynatex info DB.h5``: what a tile database holds."""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from ..player.modes import describe as describe_modes
from ..text import printable
from ..tiledb import open_db
from . import COMMANDS

#: lists longer than this print as a summary (``--json`` has them whole)
LONG_LIST = 8


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "info",
        help=COMMANDS["info"],
        description="List the textures of a tile database, their source, the methods stored for "
        "each (validating them) and the player modes that play them, then each mode's options and "
        "controls with their ranges and defaults. Long per-tile lists print as min/median/max; "
        "--json gives everything in full.",
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
            ranking = tex.ranking
            if ranking is not None:
                entry["ranking"] = ranking
            out["textures"][tex.name] = entry
        offers = describe_modes(db)
        for name, t in offers["textures"].items():
            out["textures"][name]["modes"] = t["modes"]
        out["modes"] = offers["modes"]
        return out


def summary(value: Any) -> Any:
    """A list longer than :data:`LONG_LIST` as its length and min/median/max (numbers) or its first
    entries; other values as they are (``--json`` prints every value in full)."""
    if not isinstance(value, list) or len(value) <= LONG_LIST:
        return value
    try:
        nums = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):  # strings, ragged lists
        nums = None
    if nums is not None and nums.size:
        lo, mid, hi = (f"{v:.6g}" for v in (nums.min(), np.median(nums), nums.max()))
        shape = "x".join(map(str, nums.shape))
        return f"{shape} values: min {lo}, median {mid}, max {hi} (all of them: --json)"
    return f"{len(value)} entries: {', '.join(map(str, value[:3]))}, ... (all of them: --json)"


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
        modes = t.get("modes") or []
        if modes:
            print(f"  plays as: --mode {modes[0]} (default)" + "".join(f", --mode {m}" for m in modes[1:]))
        for method, info in t["methods"].items():
            print(f"  {method}:")
            for key, value in info.items():
                value = summary(value)
                if isinstance(value, float):
                    value = f"{value:.6g}"
                print(f"    {printable(key):24s} {printable(value)}")
        if "ranking" in t:
            from .analyze import format_ranking

            print("  modes ranked against the clip (dynatex analyze --methods auto):")
            print(format_ranking(t["ranking"]))
    for mode, m in d.get("modes", {}).items():
        print(f"\nmode {mode} (plays {m['method']}): {m['summary']}")
        for title, params in (("options", m["options"]), ("controls", m["controls"])):
            if params:
                print(f"  {title}:")
                for name, p in params.items():
                    print(f"    {name:14s} {p['rule']} (default {p['default']})")
    return 0
