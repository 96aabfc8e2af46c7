"""Fuzz the tile database: mutated databases through ``info`` and a short render, outcome table.

    python tools/fuzz_databases.py [--count 5000] [--seed 16] [--start 0] [--workers 2] [--timeout 60]
                                   [--no-opencl] [--json results.jsonl] [--show-bad 20]
                                   [--structural [--max-bytes 67108864]]

Builds one small database per method with the analyzer, then runs mutants ``start ..
start + count - 1`` of ``seed`` (see ``tests/tiledb/fuzzing.py`` for the mutations and the
outcome classes) in worker processes, numpy and the first verified OpenCL device, and
prints the outcome table per method and mutation kind, then the mutants that went wrong
(garbage, error, crash, hang), each reproducible from its seed and index. Exit status 1
when any did. The test suite runs a bounded number of the same mutants
(``tests/tiledb/test_fuzz.py``). ``--structural`` runs the structural mutants instead (external
storage, virtual datasets, external and soft links, size bombs), with the workers' bound on
declared bytes per read at ``--max-bytes``, and prints a table per variant and the peak resident
memory of the workers and of their probe children.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.tiledb import fuzzing


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds one mutant may take in its worker")
    ap.add_argument("--no-opencl", action="store_true", help="render on numpy only")
    ap.add_argument("--json", help="write one JSON line per mutant here")
    ap.add_argument("--show-bad", type=int, default=20, help="list at most this many bad mutants")
    ap.add_argument("--structural", action="store_true", help="the structural mutants (links, storage, bombs)")
    ap.add_argument("--max-bytes", type=int, default=64 << 20, help="with --structural: the readers' bound")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="dynatex-fuzz-") as tmp:
        bases = fuzzing.build_bases(tmp)
        devices = [None] if args.no_opencl else fuzzing.verified_device()
        print(
            f"bases built in {time.perf_counter() - t0:.0f} s; backends: "
            f"{', '.join('numpy' if d is None else 'opencl ' + d for d in devices)}",
            flush=True,
        )
        t0 = time.perf_counter()
        results = []
        out = open(args.json, "w") if args.json else None
        for r in fuzzing.fuzz(
            bases,
            tmp,
            seed=args.seed,
            count=args.count,
            start=args.start,
            timeout=args.timeout,
            workers=args.workers,
            devices=devices,
            structural=args.structural,
            max_bytes=args.max_bytes if args.structural else None,
        ):
            results.append(r)
            if out:
                out.write(json.dumps({"spec": r.spec, "outcome": r.outcome, "steps": r.steps}) + "\n")
            if len(results) % 500 == 0:
                print(f"  {len(results)} mutants, {time.perf_counter() - t0:.0f} s", flush=True)
        if out:
            out.close()
    seconds = time.perf_counter() - t0
    print(
        f"\n{len(results)} mutants of seed {args.seed} (from {args.start}) in {seconds:.0f} s "
        f"({len(results) / seconds:.1f} per second, {args.workers} workers)\n"
    )
    print(fuzzing.table(results))
    if args.structural:
        print("\n" + fuzzing.table(results, key="variant"))
        peak = {k: max((r.rss.get(k, 0) for r in results), default=0) for k in ("self", "children")}
        print(
            f"\npeak resident memory: workers {peak['self'] / 2**20:.0f} MiB, probe children "
            f"{peak['children'] / 2**20:.0f} MiB; bound {args.max_bytes / 2**20:.0f} MiB of declared data per read, "
            f"bombs declare {fuzzing.BOMB_BYTES / 2**20:.0f} MiB"
        )
    bad = [r for r in results if r.outcome in fuzzing.BAD]
    for r in bad[: args.show_bad]:
        print(r.line())
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
