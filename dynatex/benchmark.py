"""Measuring players: frames per second, latency percentiles, the numpy reference side by
side, and the fraction of the memory-bandwidth roofline (measured in the same run)."""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable

import numpy as np

from .checks import check_int
from .player import open_player
from .tiledb import DatabaseWriter, LDSModel, SourceInfo

#: float16 vectors per work-item of the streaming copy (``BLOCKS`` in player/kernels/variants/copy_stream.cl)
COPY_BLOCKS = 64


def copy_bandwidth(*, mbytes: int = 256, repeats: int = 5) -> dict[str, float]:
    """Sustained copy bandwidth in GB/s (bytes read + written): the fastest of numpy's copy,
    an OpenCL copy with plain stores and one with streaming stores (``gbs``, the roofline).

    The roofline time of a frame is ``bytes_per_frame / gbs``. On a CPU a plain store reads
    the line it fills first, so the plain copy moves three bytes for every two it is credited
    with; the streaming copy is the one that shows the machine's bandwidth there. A read-only
    stream can beat copy bandwidth (no write traffic), so a read-bound kernel may exceed 1.0.
    """
    mbytes = check_int("mbytes", mbytes, 1, 1 << 16)
    repeats = check_int("repeats", repeats, 1, 1000)
    n = mbytes * 2**20 // 4
    src = np.ones(n, np.float32)
    dst = np.empty_like(src)
    np.copyto(dst, src)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        np.copyto(dst, src)
        times.append(time.perf_counter() - t)
    result = {"numpy_gbs": 2 * src.nbytes / np.median(times) / 1e9}
    try:
        result.update(_opencl_copy_bandwidth(src, repeats))
    except Exception as exc:  # no OpenCL: the numpy figure stands alone
        result["opencl_error"] = str(exc).splitlines()[0]
    result["gbs"] = max(result["numpy_gbs"], result.get("opencl_gbs", 0.0))
    return result


def _opencl_copy_bandwidth(src: np.ndarray, repeats: int) -> dict[str, float]:
    """GB/s of the plain copy of ``src`` (player/kernels/copy.cl) and, where the self-test
    verified it, the streaming copy (player/kernels/variants/copy_stream.cl), and the larger as ``opencl_gbs``;
    each the median of ``repeats`` after one warm-up."""
    import pyopencl as cl

    from .player.opencl.context import get_context, variant_verified
    from .player.opencl.programs import build_program

    ctx = get_context()
    queue = cl.CommandQueue(ctx)
    mf = cl.mem_flags
    a = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=src)
    b = cl.Buffer(ctx, mf.WRITE_ONLY, src.nbytes)
    copies = [("plain", build_program(ctx, "copy.cl"), src.size // 16)]
    if variant_verified(ctx.devices[0], "copy_stream"):
        copies.append(
            (
                "stream",
                build_program(ctx, "variants/copy_stream.cl", {"BLOCKS": COPY_BLOCKS}),
                src.size // (16 * COPY_BLOCKS),
            )
        )
    out = {}
    for name, prog, size in copies:
        copy = prog.kernel(f"copy_{name}")
        copy.set_args(a, b)
        cl.enqueue_nd_range_kernel(queue, copy, (size,), None).wait()
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            cl.enqueue_nd_range_kernel(queue, copy, (size,), None).wait()
            times.append(time.perf_counter() - t)
        out[f"opencl_{name}_gbs"] = 2 * src.nbytes / float(np.median(times)) / 1e9
    out["opencl_gbs"] = max(out.values())
    return out


def time_calls(fn: Callable[[], object], *, frames: int, warmup: int = 3, max_seconds: float = 20.0) -> np.ndarray:
    """Wall-clock seconds of ``frames`` calls of ``fn`` (fewer if ``max_seconds`` runs out)."""
    for _ in range(warmup):
        fn()
    out = []
    start = time.perf_counter()
    for _ in range(frames):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
        if time.perf_counter() - start > max_seconds and len(out) >= 10:
            break
    return np.array(out)


def summarize(times: np.ndarray, *, per_pass: int = 1) -> dict[str, float]:
    """Median and 99th percentile of per-frame times; with ``per_pass`` frames rendered per pass
    (a look-ahead: one call renders the pass, the others hand its frames out), the median of
    whole passes' times per frame (``times`` starts at a pass)."""
    whole = times.size // per_pass * per_pass
    med = float(np.median(times[:whole].reshape(-1, per_pass).sum(axis=1))) / per_pass if whole else np.nan
    return {
        "frames": int(times.size),
        "median_ms": med * 1e3,
        "p99_ms": float(np.percentile(times, 99)) * 1e3,
        "fps": 1.0 / med,
    }


def bench_player(
    db: str | os.PathLike,
    texture: str | None = None,
    *,
    mode: str = "lds",
    frames: int = 200,
    bandwidth_gbs: float | None = None,
    numpy_frames: int | None = None,
    options: dict | None = None,
    rounds: int = 5,
) -> dict:
    """Time ``next_frame(out=...)`` end to end on OpenCL and on the numpy reference.

    The two backends run in alternating rounds, so that both see the same machine load.
    """
    options = dict(options or {})
    per_pass = options.get("lookahead") or 1
    result: dict = {"mode": mode}
    n_frames = {"opencl": frames, "numpy": numpy_frames or max(10, frames // 4)}
    times: dict[str, list[np.ndarray]] = {"opencl": [], "numpy": []}
    with (
        open_player(db, texture, mode=mode, backend="opencl", **options) as pc,
        open_player(db, texture, mode=mode, backend="numpy", **options) as pn,
    ):
        out = np.empty(pc.shape, np.uint8)
        for r in range(rounds):
            for backend, p in (("opencl", pc), ("numpy", pn)):
                per_round = -(-max(2, n_frames[backend] // rounds) // per_pass) * per_pass
                t = time_calls(
                    lambda p=p, out=out: p.next_frame(out=out),
                    frames=per_round,
                    warmup=(3 if r == 0 else 1) * per_pass,  # whole passes: the timed calls start one
                    max_seconds=20.0 / rounds,
                )
                for _ in range(-t.size % per_pass):  # a round cut short: the next starts at a pass
                    p.next_frame(out=out)
                times[backend].append(t[: t.size // per_pass * per_pass])
        result["size"] = f"{pc.shape[1]}x{pc.shape[0]}"
        result["bytes_per_frame"] = pc.bytes_per_frame
    for backend in times:
        result[backend] = summarize(np.concatenate(times[backend]), per_pass=per_pass)
    result["speedup_vs_numpy"] = result["numpy"]["median_ms"] / result["opencl"]["median_ms"]
    if bandwidth_gbs and result.get("bytes_per_frame"):
        roof_ms = result["bytes_per_frame"] / (bandwidth_gbs * 1e9) * 1e3
        result["roofline_ms"] = roof_ms
        result["roofline_fraction"] = roof_ms / result["opencl"]["median_ms"]
        result["numpy_roofline_fraction"] = roof_ms / result["numpy"]["median_ms"]
    return result


def synthetic_lds_db(path: str | os.PathLike, width: int, height: int, *, n: int = 50, seed: int = 0) -> str:
    """Write a database with texture ``synthetic``: an ``n``-state LDS at ``width x height`` colour.

    The player's cost depends only on the sizes, so a random orthonormal-ish basis and a
    stable rotation-block transition matrix stand in for an analysed clip.
    """
    rng = np.random.default_rng(seed)
    p = width * height * 3
    basis = rng.standard_normal((n, p), dtype=np.float32)
    basis /= np.linalg.norm(basis, axis=1, keepdims=True)
    a = np.zeros((n, n))
    for i in range(0, n - 1, 2):
        t = rng.uniform(0.05, 1.0)
        a[i : i + 2, i : i + 2] = 0.97 * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    if n % 2:
        a[-1, -1] = 0.9
    b = np.eye(n) * 30
    from .analyzer.lds import stationary_covariance

    model = LDSModel(
        mean=np.full(p, 128, np.float32),
        basis=basis,
        singular_values=np.ones(n),
        A=a,
        B=b,
        x0=np.zeros(n),
        states=np.zeros((n, n + 1)),
        stationary_cov=stationary_covariance(a, b @ b.T),
        info={"synthetic": True},
    )
    # n components need at least n + 1 frames: the database refuses a model its source cannot hold
    info = SourceInfo(
        filename="<synthetic>", sha256="", fps=25.0, width=width, height=height, channels=3, n_frames=n + 1
    )
    with DatabaseWriter(path, overwrite=True) as w:
        w.put_texture("synthetic", info)
        w.put_method("synthetic", "lds", model)
    return os.fspath(path)


def bench_lds_sizes(
    sizes: list[tuple[int, int]],
    *,
    n: int = 50,
    frames: int = 200,
    precisions: tuple[str, ...] = ("float32", "float16"),
    log: Callable[[str], None] | None = None,
    bandwidth: dict | None = None,
) -> dict:
    """The LDS benchmark of the README: synthetic textures at each ``(height, width)``, both precisions."""
    bw = bandwidth or copy_bandwidth()
    report = {"bandwidth": bw, "results": []}
    with tempfile.TemporaryDirectory(prefix="dynatex-bench-") as tmp:
        for h, w in sizes:
            path = synthetic_lds_db(os.path.join(tmp, f"lds_{w}x{h}.h5"), w, h, n=n)
            for prec in precisions:
                r = bench_player(path, mode="lds", frames=frames, bandwidth_gbs=bw["gbs"], options={"precision": prec})
                r.update(precision=prec, n=n)
                report["results"].append(r)
                if log:
                    log(format_result(r))
    return report


def format_result(r: dict) -> str:
    roof = f", {r['roofline_fraction']:.2f} of roofline" if "roofline_fraction" in r else ""
    extra = f" {r['precision']}" if "precision" in r else ""
    return (
        f"{r['mode']} {r['size']}{extra}: OpenCL {r['opencl']['fps']:.0f} fps "
        f"(median {r['opencl']['median_ms']:.2f} ms, "
        f"p99 {r['opencl']['p99_ms']:.2f} ms{roof}); numpy {r['numpy']['fps']:.0f} fps "
        f"-> {r['speedup_vs_numpy']:.2f}x"
    )
