"""``dynatex bench``: frames per second, latency percentiles, numpy reference and roofline."""

from __future__ import annotations

import argparse
import json
import sys

from ..benchmark import bench_lds_sizes, bench_player, copy_bandwidth, format_result
from ..player import MODES
from ._common import UsageError, positive_int, size_arg


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "bench",
        help="benchmark the player (fps, latency, roofline, numpy side by side)",
        description="Without a database: LDS players (n=50) on synthetic textures at each "
        "--sizes, float32 and float16 bases. With a database: the chosen texture "
        "and mode. Copy bandwidth is measured in the same run for the roofline.",
    )
    p.add_argument("database", nargs="?", help="tile database to benchmark (default: synthetic LDS textures)")
    p.add_argument("--texture")
    p.add_argument("--mode", default="lds", choices=sorted(MODES))
    p.add_argument("--sizes", default="352x288,1280x720", help="WxH list for the synthetic LDS benchmark")
    p.add_argument("--n", type=positive_int, default=50, help="state order of the synthetic LDS (default 50)")
    p.add_argument("--frames", type=positive_int, default=200, help="frames timed per configuration")
    p.add_argument("--json", action="store_true", help="print one JSON document instead of lines")
    return p


def run(args: argparse.Namespace) -> int:
    log = None if args.json else print
    if args.database is None:
        try:
            sizes = [size_arg(s) for s in args.sizes.split(",") if s]
        except argparse.ArgumentTypeError as exc:
            raise UsageError(f"--sizes: {exc}") from None
        report = bench_lds_sizes(sizes, n=args.n, frames=args.frames, log=log)
    else:
        bw = copy_bandwidth()
        r = bench_player(args.database, args.texture, mode=args.mode, frames=args.frames, bandwidth_gbs=bw["gbs"])
        report = {"bandwidth": bw, "results": [r]}
        if log:
            log(format_result(r))
    if args.json:
        json.dump(report, sys.stdout, indent=2, default=float)
        print()
    else:
        print(f"copy bandwidth {report['bandwidth']['gbs']:.1f} GB/s (roofline = bytes per frame / bandwidth)")
    return 0
