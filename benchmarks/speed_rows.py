"""The projection's OpenCL rate over numpy's by basis rows: why the self-test's speed figures are
keyed by rows (``SPEED_ROWS`` in ``player/engines/projection.py``).

    python benchmarks/speed_rows.py [--device pocl] [--rows 8 20 50 150] [--repeats 2] [--json]

The self-test's own measurement (``selftest._projection_speed``: its engines and rounds) at
352x288 float32, one frame and ``SPEED_PER_PASS`` frames a pass, with the fine detail and without,
for each basis row count; each figure the median of its rounds (OpenCL's rate over numpy's: above
1, OpenCL is faster), each configuration measured ``--repeats`` times. Set ``DYNATEX_CACHE_DIR``
to keep the self-test this runs first out of the shared cache.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics

from dynatex.player.engines.projection import SPEED_PER_PASS
from dynatex.player.opencl import selftest as st


def measure(device: str, rows: list[int], repeats: int) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {}
    for _ in range(repeats):
        for n in rows:
            for detail in (False, True):
                for per_pass in (1, SPEED_PER_PASS):
                    rounds = st._projection_speed("float32", (288, 352), per_pass, detail, n)(device)
                    key = f"{n} rows, {per_pass} per pass{', detail' if detail else ''}"
                    out.setdefault(key, []).append(round(statistics.median(rounds), 2))
    st._release_speed_engines()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="pocl", help="the device (as get_context takes it)")
    ap.add_argument("--rows", type=int, nargs="+", default=[8, 20, 50, 150])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    figures = measure(args.device, args.rows, args.repeats)
    if args.json:
        print(json.dumps(figures, indent=2))
        return 0
    print(f"352x288 float32 on {args.device}, OpenCL rate / numpy rate; load average {os.getloadavg()[0]:.1f}")
    for key, values in figures.items():
        print(f"  {key}: {', '.join(f'{v:.2f}x' for v in values)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
