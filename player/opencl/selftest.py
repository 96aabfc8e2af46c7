"""The device self-test: proof, not a guess, that an OpenCL device runs dynatex's kernels.

A device is used only after every kernel, built with the defines the modes use, rendered
small inputs equal to its numpy reference (exactly where the contract is exact, within the
documented tolerance for float paths). The test runs in a child process with a timeout, so
a driver that crashes or hangs while compiling or running a kernel takes down the child,
never the caller. Verdicts are cached per (platform, platform version, device, driver
version, dynatex version, kernel sources) in the user's cache folder, so a game pays the
test once per machine and driver.

The checks open the small database shipped with the player (``player/selftest.h5``, every
method on a 48-frame 32x24 clip; ``tools/make_selftest_db.py`` rebuilds it) with every
mode on the device and with the numpy backend, and compare frames; the gather engine is
also checked directly on the defines the modes do not reach. Kernel variants
(``kernels/variants/``, not portable OpenCL C) are checked last and separately: a variant
that fails only keeps the device on its portable kernel.

Examples
--------
>>> from dynatex.player.opencl import devices, verify
>>> [v.ok for v in map(verify.verdict, devices.devices())]     # doctest: +SKIP
[True, True]

``python -m dynatex.player --check`` prints the same for every device. Environment:
``DYNATEX_CACHE_DIR`` (where verdicts are kept), ``DYNATEX_SELFTEST_TIMEOUT`` (seconds,
default 180), ``DYNATEX_PYTHON`` (the interpreter for the child where ``sys.executable`` is
an application embedding Python rather than Python itself).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict
from importlib import resources
from pathlib import Path

import numpy as np

from . import verify
from .devices import DeviceInfo, devices
from .verify import INJECT_ENV, Verdict

#: The texture of ``selftest.h5``.
TEXTURE = "selftest"


# -- the checks (run in the child) ------------------------------------------------------------
def _db_path() -> str:
    return str(resources.files("dynatex.player").joinpath("selftest.h5"))


def _compare(name: str, got: np.ndarray, want: np.ndarray, max_abs: int, max_share: float) -> str | None:
    if got.shape != want.shape:
        return f"{name}: shape {got.shape}, reference {want.shape}"
    d = np.abs(got.astype(np.int16) - want.astype(np.int16))
    share = float((d > 0).mean()) if d.size else 0.0
    if int(d.max(initial=0)) > max_abs or share > max_share:
        return (
            f"{name}: {share:.1%} of values differ from the numpy reference, by up to {int(d.max())} "
            f"(allowed {max_abs}, {max_share:.0%})"
        )
    return None


def _mode_check(
    mode: str,
    options: dict,
    *,
    frames: int = 4,
    max_abs: int = 1,
    max_share: float = 0.01,
    controls: dict | None = None,
) -> Callable[[str], str | None]:
    """Mode ``mode`` opened with ``options`` (and ``controls`` set) on the device and on numpy:
    ``frames`` frames compared."""

    def check(device: str) -> str | None:
        from .. import open_player

        with (
            open_player(_db_path(), TEXTURE, mode=mode, backend="opencl", device=device, **options) as pc,
            open_player(_db_path(), TEXTURE, mode=mode, backend="numpy", **options) as pn,
        ):
            for name, value in (controls or {}).items():
                setattr(pc, name, value)
                setattr(pn, name, value)
            out = np.empty(pc.shape, np.uint8)
            for k in range(frames):
                pc.next_frame(out=out)
                problem = _compare(f"frame {k}", out, pn.next_frame(), max_abs, max_share)
                if problem:
                    return problem
        return None

    return check


def _gather_check(
    *,
    cell,
    time_step: int,
    wrap: str,
    interpolate: bool = True,
    size=(40, 136),
    wide: bool | None = False,
    format: str = "RGB",
    misalign: int = 0,
) -> Callable[[str], str | None]:
    """The gather engine against its reference, exactly, on random maps and tones, writing
    ``format`` into an array ``misalign`` bytes past a 64-byte boundary."""

    def check(device: str) -> str | None:
        from ..engines.gather import open_gather, pack_source

        rng = np.random.default_rng(7)
        stack = rng.integers(0, 256, (6, 20, 36, 3), dtype=np.uint8)
        g = open_gather(
            stack,
            size,
            backend="opencl",
            device=device,
            wrap=wrap,
            interpolate=interpolate,
            time_step=time_step,
            cell=cell,
            wide=wide,
            format=format,
        )
        g.set_tones(rng.uniform(0.5, 1.5, (3, 3)).astype(np.float32), rng.uniform(-20, 20, (3, 3)).astype(np.float32))
        h, w = size
        if cell is None:
            idx = rng.integers(0, 20 * 36, (h, w))
            idx[: h // 2] = (np.arange(w) % 36)[None, :] + 36 * (np.arange(h // 2) % 20)[:, None]
            g.set_source_map(pack_source(idx, rng.integers(0, 3, (h, w))))
        else:
            gh, gw = -(-h // cell[0]), -(-w // cell[1])
            oy = rng.integers(0, 20 - cell[0] + 1, (gh, gw))
            ox = rng.integers(0, 36 - cell[1] + 1, (gh, gw))
            g.set_source_grid(pack_source(oy * 36 + ox, rng.integers(0, 3, (gh, gw))))
        g.set_time_map(
            rng.uniform(-3, 9, g.tmap_shape).astype(np.float32), rng.uniform(0, 4, g.tmap_shape).astype(np.float32)
        )
        out = _aligned(g.out_shape, misalign)
        for t, fade in ((0.0, 0.0), (2.3, 0.5), (-7.75, 1.0)):
            g.render(t, out, fade=fade)
            problem = _compare(f"t={t}", out, g.render_reference(t, fade=fade), 0, 0.0)
            if problem:
                return problem
        return None

    return check


def _aligned(shape: tuple[int, ...], misalign: int) -> np.ndarray:
    """An uninitialised uint8 array of ``shape`` starting ``misalign`` bytes past a 64-byte boundary."""
    n = int(np.prod(shape))
    raw = np.empty(n + 128, np.uint8)
    start = (-raw.ctypes.data) % 64 + misalign
    return raw[start : start + n].reshape(shape)


def _copy_check(device: str) -> str | None:
    """The benchmark's streaming copy (kernels/variants/copy_stream.cl) copies every byte."""
    import pyopencl as cl

    from .context import get_context
    from .programs import build_program

    ctx = get_context(device)
    queue = cl.CommandQueue(ctx)
    src = np.random.default_rng(1).random(16 * 4 * 8, dtype=np.float32)
    mf = cl.mem_flags
    a = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=src)
    b = cl.Buffer(ctx, mf.WRITE_ONLY, src.nbytes)
    kernel = build_program(ctx, "variants/copy_stream.cl", {"BLOCKS": 4}).kernel("copy_stream")
    kernel.set_args(a, b)
    cl.enqueue_nd_range_kernel(queue, kernel, (8,), None)
    out = np.zeros_like(src)
    cl.enqueue_copy(queue, out, b)
    queue.finish()
    return None if np.array_equal(out, src) else "the streaming copy lost bytes"


def random_colour_set(rng: np.random.Generator, share: float = 0.5) -> np.ndarray:
    """A valid nearest-colour map (:mod:`dynatex.tiledb.gamut`) of a random set of about ``share``
    of the bins, each other bin mapped to a random bin of the set (not the nearest: the kernel
    and its reference need only agree)."""
    bins = np.arange(32**3)
    inside = rng.random(bins.size) < share
    return np.where(inside, bins, rng.choice(bins[inside], bins.size)).astype(np.uint16)


def random_local(rng: np.random.Generator, nearest: np.ndarray, h: int, w: int, block: int):
    """Valid local colour sets (:class:`~dynatex.tiledb.gamut.LocalGamut`) within the clip's set
    ``nearest``: per region a random half of it, each cell mapped to a random bin of that half."""
    from ...tiledb.gamut import LocalGamut

    regions = -(-h // block) * -(-w // block)
    clip_set = np.flatnonzero(nearest == np.arange(32**3))
    held = np.zeros((regions, 32**3), bool)
    targets = np.empty((regions, 4096), np.uint16)
    for r in range(regions):
        mine = clip_set[rng.random(clip_set.size) < 0.5]
        held[r, mine] = True
        targets[r] = rng.choice(mine, 4096)
    return LocalGamut(block=block, inside=np.packbits(held, axis=1, bitorder="little"), nearest=targets)


def random_tone(rng: np.random.Generator, channels: int):
    """A valid tone map (:mod:`dynatex.tiledb.tone`): per channel a random increasing curve from
    -100 to about 650, its steps at least two lookup bins wide."""
    from ...tiledb.tone import BINS, ToneModel

    steps = rng.exponential(1.0, (channels, 255)) ** 3 + 0.01
    curves = np.concatenate([np.zeros((channels, 1)), np.cumsum(steps, axis=1)], axis=1)
    curves = -100 + 500 * curves / curves[:, -1:] + np.arange(256) * (2.0 * 500 / BINS)
    return ToneModel(forward=curves.astype(np.float32))


def _detail_check(channels: int, format: str, tone: bool = False, local: bool = False) -> Callable[[str], str | None]:
    """The projection kernel with the detail fused, 3 frames per pass and one at a time, against
    its reference, exactly: a basis and coefficients whose sums are exact in float32 in any
    order, and a random volume, gain and colour range (and, in colour, a random colour set;
    with ``tone``, a random tone map; with ``local``, random colour sets of 8-pixel regions)."""

    def check(device: str) -> str | None:
        import pyopencl as cl

        from ...tiledb.detail import DetailModel
        from ...tiledb.gamut import GamutModel
        from ..engines.projection import open_projector
        from ..pixels import FORMATS
        from .context import get_context

        rng = np.random.default_rng(5)
        h, w, fmt = 21, 37, FORMATS[format]
        low = rng.integers(0, 128, (h, w, channels), dtype=np.uint8)
        model = DetailModel(
            volume=rng.integers(-127, 128, (4, 9, 14, channels), dtype=np.int8),
            gain=rng.uniform(0, 0.5, (h, w)).astype(np.float32),
            low=low,
            high=low + rng.integers(0, 128, (h, w, channels), dtype=np.uint8),
            colours=rng.integers(0, 2, 32**3, dtype=np.uint8),
        )
        basis = rng.integers(-8, 9, (4, h * w * channels)).astype(np.float32)
        mean = rng.integers(-40, 300, h * w * channels).astype(np.float32)
        ctx = get_context(device)
        shape = (h, w, fmt.bytes)
        kw = {"shape": shape, "channels": channels, "format": format, "frames": 3, "detail": model}
        if channels == 3:
            nearest = random_colour_set(rng)
            kw["gamut"] = GamutModel(nearest, local=random_local(rng, nearest, h, w, 8) if local else None)
        if tone:
            kw["tone"] = random_tone(rng, channels)
        engine = open_projector(basis, mean, ctx=ctx, queue=cl.CommandQueue(ctx), **kw)
        ref = open_projector(basis, mean, **kw)
        try:
            engine.coefs[:] = ref.coefs[:] = rng.integers(-4, 5, (3, 4))
            layers = [ref.detail.layers(11, k, 1.3) for k in (0, 7, 40)]
            want, got = np.empty((3, *shape), np.uint8), np.empty((3, *shape), np.uint8)
            ref.run(want, count=3, layers=layers)
            engine.run(got, count=3, layers=layers)
            problem = _compare("3 frames per pass", got, want, 0, 0.0)
            if problem:
                return problem
            engine.coef[:] = ref.coefs[1]
            engine.run(got[0], layers=[layers[1]])
            return _compare("one frame", got[0], want[1], 0, 0.0)
        finally:
            engine.close()

    return check


def _warp_check(format: str, step: int) -> Callable[[str], str | None]:
    """Motion-compensated crossfades (kernels/warp.cl) against the reference, exactly, on random frames and
    flows reaching past the frame's edges."""

    def check(device: str) -> str | None:
        import pyopencl as cl

        from ...tiledb.turnpoints import FlowModel, flow_grid
        from ..engines.blend import open_blend
        from ..engines.warp import WarpBlend, warp_reference
        from ..pixels import FORMATS
        from .context import get_context

        rng = np.random.default_rng(9)
        h, w = 19, 45
        frames = rng.integers(0, 256, (4, h, w, 3), dtype=np.uint8)
        flows = rng.integers(-500, 501, (2, *flow_grid(h, w, step), 2)).astype(np.int16)
        flow = FlowModel(pairs=np.array([[0, 2], [3, 1]], np.int32), flows=flows, step=step)
        ctx = get_context(device)
        queue = cl.CommandQueue(ctx)
        engine = WarpBlend(open_blend(frames, ctx=ctx, queue=queue, format=format), flow, ctx=ctx, queue=queue)
        stack = FORMATS[format].from_rgb(frames)
        try:
            for (a, wa), (b, wb), k in (((0, 205), (2, 51), 0), ((3, 128), (1, 128), 1), ((3, 26), (1, 230), 1)):
                out = np.empty(stack.shape[1:], np.uint8)
                engine.render(((a, wa), (b, wb)), out)
                want = warp_reference(stack, a, b, wa, wb, flows[k], step.bit_length() - 1, np.empty_like(out))
                problem = _compare(f"pair {a}, {b}", out, want, 0, 0.0)
                if problem:
                    return problem
        finally:
            engine.close()
        return None

    return check


def _stochastic_check(format: str, toned: bool, small: bool) -> Callable[[str], str | None]:
    """The stochastic tiling engine against its reference, exactly, on a random torus and time
    offsets faded between two maps, with a tone or without; ``small`` cells blend almost
    everywhere in short pieces, the large cell with a wide band has whole pieces of both kinds
    (the vector stores; a four-byte format's put16) and short ones."""

    def check(device: str) -> str | None:
        from ..engines.stochastic import StochasticOpenCL

        rng = np.random.default_rng(11)
        torus = rng.integers(0, 256, (5, 30, 96, 3), dtype=np.uint8)
        cell, band = ((9, 14), 0.1) if small else ((20, 96), 0.5)
        s = StochasticOpenCL(torus, (41, 133), device=device, seed=2, cell=cell, band=band, format=format)
        try:
            s.set_time_map(
                rng.uniform(-3, 9, s.tmap_shape).astype(np.float32), rng.uniform(0, 4, s.tmap_shape).astype(np.float32)
            )
            if toned:
                s.set_tones(np.array([[1.2, 0.9, 1.0]], np.float32))
            for t, fade in ((0.0, 0.0), (2.3, 0.5), (-7.75, 1.0)):
                problem = _compare(f"t={t}", s.render(t, fade=fade), s.render_reference(t, fade=fade), 0, 0.0)
                if problem:
                    return problem
        finally:
            s.close()
        return None

    return check


_TILES = ("tiles", {"seed": 3, "size": (136, 72), "tone": "consensus"})

#: name -> check(device) returning None or what failed; run in this order, portable kernels only
CHECKS: dict[str, Callable[[str], str | None]] = {
    "gather: per-pixel source, time step 1, loop": _gather_check(cell=None, time_step=1, wrap="loop"),
    "gather: cell grid, time step 8, clamp": _gather_check(cell=(8, 12), time_step=8, wrap="clamp"),
    "gather: per-pixel source, time step 8, ping-pong, nearest": _gather_check(
        cell=None, time_step=8, wrap="pingpong", interpolate=False
    ),
    "gather: cell grid, time step 3": _gather_check(cell=(5, 7), time_step=3, wrap="loop"),
    "stochastic tiling, RGB": _stochastic_check("RGB", False, small=False),
    "stochastic tiling, RGB, toned": _stochastic_check("RGB", True, small=True),
    "stochastic tiling, BGRA, toned": _stochastic_check("BGRA", True, small=False),
    "projection with detail, RGB": _detail_check(3, "RGB"),
    "projection with detail, grey to BGRA": _detail_check(1, "BGRA"),
    "projection with detail and tone map, RGB": _detail_check(3, "RGB", tone=True),
    "projection with detail and local colour sets, BGRA": _detail_check(3, "BGRA", local=True),
    "mode lds, float32": _mode_check("lds", {"seed": 3}),
    "mode lds, 3 frames per pass": _mode_check("lds", {"seed": 3, "lookahead": 3}, frames=5),
    "mode lds, float16": _mode_check("lds", {"seed": 3, "precision": "float16"}),
    "mode mixture, float32": _mode_check("mixture", {"seed": 3}),
    "mode mixture, float16": _mode_check("mixture", {"seed": 3, "precision": "float16"}),
    "mode turnpoints": _mode_check("turnpoints", {"seed": 3}, frames=8, max_abs=0, max_share=0.0),
    "mode turnpoints, slow, crossfades": _mode_check(
        "turnpoints",
        {"seed": 3, "playback": "jumps"},
        frames=24,
        max_abs=0,
        max_share=0.0,
        controls={"speed": 0.37, "crossfade": 4},
    ),
    "mode turnpoints, RGBA, slow, crossfades": _mode_check(
        "turnpoints",
        {"seed": 3, "playback": "jumps", "format": "RGBA"},
        frames=24,
        max_abs=0,
        max_share=0.0,
        controls={"speed": 0.37, "crossfade": 4},
    ),
    "turn-point warp, RGB": _warp_check("RGB", 4),
    "turn-point warp, BGRA, step 16": _warp_check("BGRA", 16),
    "mode tiles": _mode_check(*_TILES),
    "mode evolve": _mode_check("evolve", {"seed": 3, "jitter": 2.0}, frames=6, max_share=1.0),
    "mode evolve, BGRA": _mode_check("evolve", {"seed": 3, "jitter": 2.0, "format": "BGRA"}, frames=6, max_share=1.0),
    "mode evolve, rate map": _mode_check(
        "evolve",
        {"seed": 3, "rate_sigma": 4.0, "rate_map": np.linspace(0.5, 2, 48 * 64).reshape(48, 64)},
        frames=6,
        max_share=1.0,
    ),
}

#: kernel variant (each file of ``kernels/variants/``) -> the checks that must pass before a device
#: uses it (run after CHECKS)
CHECK_VARIANTS: dict[str, dict[str, Callable[[str], str | None]]] = {
    "gather_wide": {
        "grid": _gather_check(cell=(8, 12), time_step=8, wrap="loop", size=(72, 200), wide=True),
        "per-pixel source": _gather_check(cell=None, time_step=8, wrap="clamp", size=(40, 136), wide=True),
        "grid, BGRA, aligned": _gather_check(
            cell=(8, 12), time_step=8, wrap="loop", size=(40, 256), wide=True, format="BGRA"
        ),
        "grid, RGBA, 32 bytes off": _gather_check(
            cell=(8, 12), time_step=8, wrap="pingpong", size=(40, 272), wide=True, format="RGBA", misalign=32
        ),
        "per-pixel source, RGBA, odd size": _gather_check(
            cell=None, time_step=8, wrap="clamp", size=(37, 141), wide=True, format="RGBA", misalign=16
        ),
        "mode tiles": _mode_check(*_TILES),
    },
    "copy_stream": {"copy": lambda device: _copy_check(device)},
}


def _inject_check(path: str) -> Callable[[str], str | None]:
    def check(device: str) -> str | None:
        import pyopencl as cl

        from .context import get_context

        ctx = get_context(device)
        queue = cl.CommandQueue(ctx)
        src = np.arange(4096, dtype=np.uint32).astype(np.uint8)
        dst = np.zeros_like(src)
        mf = cl.mem_flags
        a = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=src)
        b = cl.Buffer(ctx, mf.WRITE_ONLY, dst.nbytes)
        prog = cl.Program(ctx, Path(path).read_text()).build()
        prog.check(queue, (src.size,), None, a, b)
        cl.enqueue_copy(queue, dst, b)
        queue.finish()
        return _compare("injected kernel", dst, src, 0, 0.0)

    return check


def child_main(info: dict) -> None:
    """What the self-test's child runs (:func:`~dynatex.player.opencl.verify.run_child`, through
    :func:`dynatex.child.call`): every check on the device ``info`` describes."""
    _child(DeviceInfo(**info))


def _child(expected: DeviceInfo) -> int:
    """Run every check on device ``expected`` and print progress lines and the verdict (JSON)."""
    import warnings

    warnings.simplefilter("ignore")  # compiler chatter is not a verdict
    index = expected.index
    info = next((d for d in devices() if d.index == index), None)
    if info != expected:
        v = Verdict(False, f"device {index} is not {expected.describe()} in the self-test's process")
        print(f"verdict\t{json.dumps(asdict(v))}", flush=True)
        return 0
    start = time.perf_counter()
    verify.suppose(info)  # portable kernels only, until the variants' own checks
    checks = dict(CHECKS)
    if os.environ.get(INJECT_ENV):
        checks = {"injected kernel": _inject_check(os.environ[INJECT_ENV]), **checks}
    v = Verdict(ok=True, device=info.describe())
    for check_name, check in checks.items():
        problem = _run_one(check_name, check, index)
        if problem:
            v.ok, v.reason = False, f"{check_name}: {problem}"
            break
    if v.ok:
        for variant, vchecks in CHECK_VARIANTS.items():
            verify.suppose(info, frozenset({variant}))
            if not info.is_cpu:
                v.variants[variant] = False
                v.variant_reasons[variant] = "CPU devices only"
                continue
            problem = _run_one(f"variant {variant}", lambda d, vchecks=vchecks: _all(vchecks, d), index)
            v.variants[variant] = problem is None
            if problem:
                v.variant_reasons[variant] = problem
    if v.ok:
        config = verify.speed_config()
        for engine in SELFTEST_SPEED_CASES:
            print(f"check\tspeed {engine}", flush=True)
            try:
                v.speed[engine] = verify.speed_figure(SPEED_CASES[engine](index), at=time.time(), config=config)
            except Exception as exc:  # a measurement that fails decides nothing: OpenCL stays
                print(f"fail\tspeed {engine}\t{_one_line(exc)}", flush=True)
            else:
                print(f"pass\tspeed {engine}", flush=True)
        _speed_held.release()
    v.seconds = time.perf_counter() - start
    print(f"verdict\t{json.dumps(asdict(v))}", flush=True)
    return 0


def _projection_speed(precision: str, size: tuple[int, int], per_pass: int, detail: bool, rows: int):
    """The projection engine (lds, mixture) at ``size`` through ``rows`` basis rows with
    ``per_pass`` frames per pass (a look-ahead), with a fine detail or without, OpenCL against
    numpy: the per-round ratios of :func:`measure_rounds`."""

    def measure(device: str) -> list[float]:
        from ..engines.projection import SPEED_PER_PASS

        engines = _speed_engines(device, precision, size, SPEED_PER_PASS, detail, rows)
        h, w = size
        out = np.empty((per_pass, h, w, 3), np.uint8)
        d = engines[1].detail
        layers = [d.layers(3, k, 1.0) for k in range(per_pass)] if detail else None
        if per_pass == 1:  # a player without look-ahead: one frame from coef, as it runs
            calls = [lambda e=e: e.run(out[0], layers=layers) for e in engines]
        else:
            calls = [lambda e=e: e.run(out, count=per_pass, layers=layers) for e in engines]
        return measure_rounds(*calls)

    return measure


class _HeldEngines:
    """The last pair of speed engines made (OpenCL, numpy) and the case they were made for: the
    cases of 1 and 8 frames per pass of one size share them."""

    def __init__(self) -> None:
        self.key: tuple | None = None
        self.engines: list | None = None

    def get(self, key: tuple) -> list | None:
        return self.engines if key == self.key else None

    def hold(self, key: tuple, engines: list) -> None:
        self.release()
        self.key, self.engines = key, engines

    def release(self) -> None:
        if self.engines is not None:
            self.engines[0].close()  # the numpy reference holds nothing on a device
        self.key = self.engines = None


_speed_held = _HeldEngines()


def _speed_engines(device: str, precision: str, size: tuple[int, int], frames: int, detail: bool, n: int = 50) -> list:
    """The OpenCL engine and its numpy reference on a basis of ``n`` rows at ``size``, with a detail
    model of the analyser's shape (a 32 x 128 x 128 volume) or none, held until other ones are asked."""
    import pyopencl as cl

    from ...tiledb.detail import DetailModel
    from ..engines.projection import open_projector
    from .context import get_context

    key = (device, precision, size, frames, detail, n)
    held = _speed_held.get(key)
    if held is not None:
        return held
    _speed_held.release()
    h, w = size
    rng = np.random.default_rng(0)
    # speed does not depend on the values: a random block repeated is as good and quick to make
    block = (rng.standard_normal((n, 4096), dtype=np.float32) * 0.1).astype(precision)
    basis = np.resize(block, (n, h * w * 3))
    mean = np.full(h * w * 3, 128, np.float32)
    model = None
    if detail:
        model = DetailModel(
            volume=rng.integers(-20, 21, (32, 128, 128, 3), dtype=np.int8),
            gain=np.full((h, w), 0.5, np.float32),
            low=np.full((h, w, 3), 16, np.uint8),
            high=np.full((h, w, 3), 240, np.uint8),
            colours=np.ones(32**3, np.uint8),
        )
    ctx = get_context(device)
    engines = [
        open_projector(
            basis,
            mean,
            shape=(h, w, 3),
            channels=3,
            ctx=c,
            queue=c and cl.CommandQueue(c),
            frames=frames,
            detail=model,
        )
        for c in (ctx, None)
    ]
    for e in engines:
        e.coefs[:] = rng.standard_normal(e.coefs.shape)
    _speed_held.hold(key, engines)
    return engines


def measure_rounds(
    opencl: Callable[[], object], numpy: Callable[[], object], *, block_s: float = 0.05, budget_s: float = 5.0
) -> list[float]:
    """OpenCL's rate over numpy's per round: each round times a block of calls of one, then of
    the other (the order alternating, so neither always runs first under a changing load),
    blocks of ``block_s`` seconds or more, after warm-up calls. At least
    :data:`~.verify.MIN_ROUNDS` rounds over :data:`~.verify.MIN_SECONDS` seconds, more while the
    figure is unsettled (:func:`~.verify.speed_settled`), up to :data:`~.verify.MAX_ROUNDS` or
    ``budget_s`` seconds."""
    for f in (opencl, numpy):  # kernels built, caches and thread pools warm
        f()
    t = time.perf_counter()
    numpy()
    calls = max(1, min(64, round(block_s / max(time.perf_counter() - t, 1e-6))))

    def block(f: Callable[[], object]) -> float:
        t = time.perf_counter()
        for _ in range(calls):
            f()
        return time.perf_counter() - t

    ratios: list[float] = []
    start = time.perf_counter()
    while len(ratios) < verify.MAX_ROUNDS:
        if len(ratios) % 2:
            t_cl, t_np = block(opencl), block(numpy)
        else:
            t_np, t_cl = block(numpy), block(opencl)
        ratios.append(t_np / t_cl)
        spent = time.perf_counter() - start
        if len(ratios) >= verify.MIN_ROUNDS and spent >= verify.MIN_SECONDS:
            if verify.speed_settled(ratios) or spent > budget_s:
                break
    return ratios


def _speed_cases() -> dict[str, Callable[[str], list[float]]]:
    from ..engines.projection import SPEED_PER_PASS, SPEED_ROWS, SPEED_SIZES, speed_case

    cases = {}
    for h, w in SPEED_SIZES:
        for rows in SPEED_ROWS:
            for precision in ("float32", "float16"):
                for detail in (False, True):
                    for per_pass in (1, SPEED_PER_PASS):
                        cases[speed_case(precision, h * w * 3, per_pass, detail, rows)] = _projection_speed(
                            precision, (h, w), per_pass, detail, rows
                        )
    return cases


#: engine -> measure(device): its OpenCL rate over its numpy reference's, one ratio per round
#: (:func:`measure_rounds`; :func:`.verify.speed_figure` sums them up in the verdict)
SPEED_CASES: dict[str, Callable[[str], list[float]]] = _speed_cases()
#: the cases the self-test measures after its checks (the smallest size, lds's default rows: a few
#: seconds); the others are measured by ``--check`` or by the first player that needs one
#: (:func:`.verify.speed`)
SELFTEST_SPEED_CASES = tuple(e for e in SPEED_CASES if " 352x288" in e and " rows" not in e)


def speed_main(info: dict, engines: list[str] | None, figures: dict | None = None) -> dict[str, list[float]]:
    """What a re-measurement's child runs (:func:`.verify.refresh_speeds`): the rounds of each of
    ``engines`` (None: those of :data:`SPEED_CASES` whose figure in ``figures`` is due,
    :func:`.verify.speed_stale`, other basis rows than the self-test's only where a player has
    measured them before) on the device ``info`` describes, which passed its checks."""
    import warnings

    warnings.simplefilter("ignore")
    if engines is None:
        now, config, figures = time.time(), verify.speed_config(), figures or {}
        engines = [
            e
            for e in SPEED_CASES
            if (e in figures or " rows" not in e) and verify.speed_stale(figures.get(e), now=now, config=config)
        ]
        if not engines:
            return {}
    expected = DeviceInfo(**info)
    found = next((d for d in devices() if d.index == expected.index), None)
    if found != expected:
        raise RuntimeError(f"device {expected.index} is not {expected.describe()} in this process")
    verify.suppose(found)
    try:
        return {e: SPEED_CASES[e](found.index) for e in engines if e in SPEED_CASES}
    finally:
        _speed_held.release()


def _all(checks: dict[str, Callable[[str], str | None]], device: str) -> str | None:
    for name, check in checks.items():
        problem = check(device)
        if problem:
            return f"{name}: {problem}"
    return None


def _one_line(exc: Exception) -> str:
    """An exception in one line; for a build failure, the file and the compiler's first error."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    errors = [ln for ln in lines[1:] if "error" in ln.lower() and "errors generated" not in ln]
    head = lines[0] if lines else ""
    if errors:
        head = head.split(" with ")[0] + ": " + errors[0]
    return f"{type(exc).__name__}: {head[:300]}"


def _run_one(name: str, check: Callable[[str], str | None], device: str) -> str | None:
    print(f"check\t{name}", flush=True)
    try:
        problem = check(device)
    except Exception as exc:  # any failure is the device's verdict
        problem = _one_line(exc)
    if problem:
        print(f"fail\t{name}\t{problem}", flush=True)
    else:
        print(f"pass\t{name}", flush=True)
    return problem
