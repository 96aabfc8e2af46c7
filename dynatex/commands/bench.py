"""``dynatex bench``: frames per second, latency percentiles, numpy reference and roofline."""

from __future__ import annotations

import argparse
import json
import sys

from ..benchmark import bench_lds_sizes, bench_player, copy_bandwidth, format_result
from ..player import MODES, player_class
from . import COMMANDS
from ._common import UsageError, positive_int, size_arg
from ._modes import known_count, mode_name, resolve_args_mode


def add_parser(sub, argv: list[str] | None = None) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "bench",
        help=COMMANDS["bench"],
        description="Without a database: LDS players (n=50) on synthetic textures at each "
        "--sizes, float32 and float16 bases. With a database: the chosen texture "
        "and mode. Copy bandwidth is measured in the same run for the roofline.",
    )
    p.add_argument("database", nargs="?", help="tile database to benchmark (default: synthetic LDS textures)")
    p.add_argument("--texture")
    p.add_argument(
        "--mode",
        type=mode_name,
        default=None,
        choices=sorted(MODES),
        help="player mode of a database's texture (default: the texture's own, as in `dynatex play`)",
    )
    p.add_argument(
        "--size",
        type=size_arg,
        default=None,
        metavar="WxH",
        help="output size of a mode that plays any size (tiles; default the source's)",
    )
    p.add_argument("--sizes", default="352x288,1280x720", help="WxH list for the synthetic LDS benchmark")
    p.add_argument("--n", type=positive_int, default=50, help="state order of the synthetic LDS (default 50)")
    p.add_argument("--frames", type=positive_int, default=200, help="frames timed per configuration")
    p.add_argument("--json", action="store_true", help="print one JSON document instead of lines")
    return p


def run(args: argparse.Namespace) -> int:
    log = None if args.json else print
    if args.database is None:
        if args.size is not None or args.mode is not None:
            raise UsageError("--size and --mode belong to a database's benchmark (synthetic LDS: --sizes)")
        try:
            sizes = [size_arg(s) for s in args.sizes.split(",") if s]
        except argparse.ArgumentTypeError as exc:
            raise UsageError(f"--sizes: {exc}") from None
        report = bench_lds_sizes(sizes, n=args.n, frames=args.frames, log=log)
    else:
        resolve_args_mode(args)
        options = known_count(player_class(args.mode), {} if args.size is None else {"size": args.size})
        bw = copy_bandwidth()
        r = bench_player(
            args.database, args.texture, mode=args.mode, frames=args.frames, bandwidth_gbs=bw["gbs"], options=options
        )
        report = {"bandwidth": bw, "results": [r]}
        if log:
            log(format_result(r))
    if args.json:
        json.dump(report, sys.stdout, indent=2, default=float)
        print()
    else:
        print(f"copy bandwidth {report['bandwidth']['gbs']:.1f} GB/s (roofline = bytes per frame / bandwidth)")
    return 0
