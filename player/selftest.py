"""The device self-test: proof, not a guess, that an OpenCL device runs dynatex's kernels.

A device is used only after every kernel, built with the defines the modes use, rendered
small inputs equal to its numpy reference (exactly where the contract is exact, within the
documented tolerance for float paths). The test runs in a child process with a timeout, so
a driver that crashes or hangs while compiling or running a kernel takes down the child,
never the caller. Verdicts are cached per (platform, platform version, device, driver
version, dynatex version, kernel sources) in the user's cache folder, so a game pays the
test once per machine and driver.

The checks open the small database shipped beside this module (``selftest.h5``, every
method on a 48-frame 32x24 clip; ``tools/make_selftest_db.py`` rebuilds it) with every
mode on the device and with the numpy backend, and compare frames; the gather engine is
also checked directly on the defines the modes do not reach. Kernel variants
(``kernels/variants/``, not portable OpenCL C) are checked last and separately: a variant
that fails only keeps the device on its portable kernel.

Examples
--------
>>> from dynatex.player import selftest
>>> [v.ok for v in map(selftest.verdict, selftest.devices())]     # doctest: +SKIP
[True, True]

``python -m dynatex.player --check`` prints the same for every device. Environment:
``DYNATEX_CACHE_DIR`` (where verdicts are kept), ``DYNATEX_SELFTEST_TIMEOUT`` (seconds,
default 180), ``DYNATEX_PYTHON`` (the interpreter for the child where ``sys.executable`` is
an application embedding Python rather than Python itself).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from .opencl import DeviceInfo, devices

#: Seconds a device's whole self-test may take before it counts as hung
#: (environment variable ``DYNATEX_SELFTEST_TIMEOUT`` overrides).
TIMEOUT = 180.0
#: Environment variable naming an extra ``.cl`` file to check first (kernel ``check(src, dst)``
#: must copy 4096 bytes): how the tests inject a kernel that crashes, hangs or computes wrong.
INJECT_ENV = "DYNATEX_SELFTEST_INJECT"
#: The texture of ``selftest.h5``.
TEXTURE = "selftest"
#: Set in the self-test's child process: the kernel variants it may use (None: the cached verdicts decide).
ALLOWED_VARIANTS: frozenset[str] | None = None

_lock = threading.Lock()
_run_lock = threading.Lock()
_verdicts: dict[str, Verdict] = {}


@dataclass
class Verdict:
    """The self-test's finding for one device."""

    ok: bool
    reason: str = ""  # what failed, one line ("" when ok)
    variants: dict[str, bool] = field(default_factory=dict)
    variant_reasons: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    device: str = ""
    tested: bool = True  # False: the child never reached a check (not the device's fault)
    #: engine -> its OpenCL frame rate over its numpy reference's, measured once after the checks
    #: (:data:`SPEED_CASES`); ``backend="auto"`` takes numpy for an engine below 1
    speed: dict[str, float] = field(default_factory=dict)


# -- cache ---------------------------------------------------------------------------------
def cache_path() -> Path:
    """Where verdicts are kept: ``devices.json`` in dynatex's cache folder (``$DYNATEX_CACHE_DIR``,
    else the platform's user cache folder; :func:`dynatex.tiledb.probe.cache_dir`)."""
    from ..tiledb.probe import cache_dir

    return cache_dir() / "devices.json"


@functools.lru_cache(maxsize=1)
def _sources_hash() -> str:
    """A digest of everything a verdict depends on besides the device: the player's modules,
    kernels and the self-test's database (read once per process)."""
    h = hashlib.sha256()
    for item in sorted(_walk(resources.files("dynatex.player")), key=lambda r: str(r)):
        h.update(item.name.encode() + b"\0" + item.read_bytes())
    return h.hexdigest()[:16]


def _walk(folder):
    for item in folder.iterdir():
        if item.is_dir():
            if item.name != "__pycache__":
                yield from _walk(item)
        elif item.name.endswith((".cl", ".py", ".h5")):
            yield item


def _version() -> str:
    from .. import __version__

    return __version__


def cache_key(info: DeviceInfo) -> str:
    """The key a device's verdict is cached under (changes with its driver and with dynatex)."""
    inject = os.environ.get(INJECT_ENV, "")
    if inject:
        inject = hashlib.sha256(Path(inject).read_bytes()).hexdigest()[:16] if Path(inject).is_file() else inject
    parts = [
        info.platform,
        info.platform_version,
        info.name,
        info.vendor,
        info.driver_version,
        _version(),
        _sources_hash(),
        inject,
    ]
    return hashlib.sha256("\x1f".join(parts).encode()).hexdigest()[:24]


def _read_cache() -> dict:
    try:
        data = json.loads(cache_path().read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write_cache(key: str, verdict: Verdict) -> None:
    """Add one verdict to the cache file atomically; a cache that cannot be written is only logged."""
    path = cache_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        data = _read_cache()
        data[key] = asdict(verdict)
        fd, tmp = tempfile.mkstemp(prefix=".devices.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=1, sort_keys=True)
        os.replace(tmp, path)
    except OSError as exc:
        from .opencl import log

        log.warning("cannot cache the OpenCL self-test verdict in %s: %s", path, exc)


def cached_verdict(info: DeviceInfo) -> Verdict | None:
    """The verdict already known for ``info`` (this process or the cache file), else None."""
    key = cache_key(info)
    with _lock:
        if key in _verdicts:
            return _verdicts[key]
    entry = _read_cache().get(key)
    if not isinstance(entry, dict):
        return None
    try:
        v = Verdict(**entry)
    except TypeError:
        return None
    with _lock:
        _verdicts[key] = v
    return v


def verdict(info: DeviceInfo, *, refresh: bool = False) -> Verdict:
    """The self-test verdict for ``info``: cached, or found now in a child process and cached.

    Self-tests run one at a time (two threads opening players wait for one test). A child
    that could not start or run its first check (no interpreter, an import failure) says
    nothing about the device: that verdict is not kept."""
    if not refresh:
        v = cached_verdict(info)
        if v is not None:
            return v
    with _run_lock:
        if not refresh:
            v = cached_verdict(info)
            if v is not None:
                return v
        v = run_child(info)
        if v.tested:
            key = cache_key(info)
            with _lock:
                _verdicts[key] = v
            _write_cache(key, v)
    return v


# -- the parent's side ------------------------------------------------------------------------
def run_child(info: DeviceInfo, *, timeout: float | None = None) -> Verdict:
    """Run the checks for ``info`` in a child process; a crash or hang there is a failed verdict."""
    if timeout is None:
        timeout = float(os.environ.get("DYNATEX_SELFTEST_TIMEOUT", TIMEOUT))
    python = os.environ.get("DYNATEX_PYTHON") or sys.executable
    if not python or "python" not in Path(python).name.lower():
        # embedded in an application whose executable is not Python: running it could start the app
        return Verdict(
            False,
            f"cannot run the self-test: {python!r} is not a Python interpreter (set DYNATEX_PYTHON to one)",
            device=info.describe(),
            tested=False,
        )
    cmd = [python, "-m", "dynatex.player.selftest", json.dumps(asdict(info))]
    env = dict(os.environ)
    env.pop("PYTHONFAULTHANDLER", None)  # any value turns it on: its dump is not our protocol
    start = time.perf_counter()
    try:
        proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            errors="replace",
            env=env,
            start_new_session=os.name == "posix",
        )
    except OSError as exc:
        return Verdict(False, f"cannot start the self-test: {exc}", device=info.describe(), tested=False)
    hung = False
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        hung = True
        _kill(proc)
        try:
            out, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:  # something else still holds the pipes: give up on them
            out, err = "", ""
    seconds = time.perf_counter() - start
    try:
        return _parse(out, None if hung else proc.returncode, hung, timeout, seconds, info, err)
    except (ValueError, TypeError) as exc:
        return Verdict(False, f"unreadable self-test verdict ({exc})", device=info.describe(), tested=False)


def _kill(proc: subprocess.Popen) -> None:
    """Kill the child and whatever it started (a compiler), so nothing keeps the pipes open."""
    if os.name == "posix":
        import signal

        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            proc.kill()
    else:
        proc.kill()


def _parse(
    out: str, code: int | None, hung: bool, timeout: float, seconds: float, info: DeviceInfo, err: str = ""
) -> Verdict:
    """The verdict from the child's lines (tab-separated: check NAME, pass NAME, fail NAME WHY,
    verdict JSON) and how it ended (``code`` None: killed after ``timeout``)."""
    passed, current, failures, final, started = [], None, {}, None, False
    for line in out.splitlines():
        word, _, rest = line.partition("\t")
        if word == "check":
            current, started = rest, True
        elif word == "pass":
            passed.append(rest)
            current = None
        elif word == "fail":
            name, _, why = rest.partition("\t")
            failures[name] = why
            current = None
        elif word == "verdict":
            final = rest
    if final is not None and code == 0:
        v = Verdict(**json.loads(final))
        v.seconds = seconds
        return v
    if not started and not hung and (code is None or code >= 0):
        last = err.strip().splitlines()[-1] if err.strip() else f"exit status {code}"
        return Verdict(
            False, f"the self-test could not run: {last[:300]}", seconds=seconds, device=info.describe(), tested=False
        )
    if hung:
        what = f"hung (no verdict after {timeout:.0f} s)"
    elif code is not None and code < 0:
        what = f"crashed (signal {-code})" + (" at exit, after its checks" if final is not None else "")
    else:
        what = f"exited with status {code}" + (" after its checks" if final is not None else "")
    where = f" in check {current!r}" if current else ""
    # variants and speed measurements come after every portable check has passed
    failed = [(k, why) for k, why in failures.items() if not k.startswith(("variant ", "speed "))]
    portable_done = not failed and current is not None and current.startswith(("variant ", "speed "))
    reason = f"{failed[0][0]}: {failed[0][1]}" if failed else "" if portable_done else f"{what}{where}"
    v = Verdict(ok=portable_done, reason=reason, seconds=seconds, device=info.describe())
    for name in CHECK_VARIANTS:
        check = f"variant {name}"
        v.variants[name] = check in passed
        if check == current:
            v.variant_reasons[name] = f"{what}{where}"
        elif check in failures:
            v.variant_reasons[name] = failures[check]
    return v


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
        from . import open_player

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
        from .gather import open_gather, pack_source

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

    from .opencl import build_program, get_context

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


def _detail_check(channels: int, format: str) -> Callable[[str], str | None]:
    """The detail engine against its reference, exactly, on a random volume, gain and colour range."""

    def check(device: str) -> str | None:
        import pyopencl as cl

        from ..tiledb.detail import DetailModel
        from .detail import DetailOpenCL, DetailReference
        from .opencl import get_context
        from .pixels import FORMATS

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
        frame = rng.integers(0, 256, (h, w, fmt.bytes), dtype=np.uint8)
        ctx = get_context(device)
        queue = cl.CommandQueue(ctx)
        src = cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=frame)
        shape = (h, w, fmt.bytes)
        engine = DetailOpenCL(model, shape=shape, channels=channels, src=src, ctx=ctx, queue=queue, format=format)
        ref = DetailReference(model, shape=shape, channels=channels, format=format)
        try:
            for k in (0, 7, 40):
                layers = ref.layers(11, k, 1.3)
                out = np.empty_like(frame)
                engine.run(layers, out)
                problem = _compare(f"frame {k}", out, ref.apply(frame, layers, out=np.empty_like(frame)), 0, 0.0)
                if problem:
                    return problem
        finally:
            engine.close()
            src.release()
        return None

    return check


def _stochastic_check(format: str, toned: bool) -> Callable[[str], str | None]:
    """The stochastic tiling engine against its reference, exactly, on a random torus and time
    offsets faded between two maps, with a tone or without."""

    def check(device: str) -> str | None:
        from .stochastic import open_stochastic

        rng = np.random.default_rng(11)
        torus = rng.integers(0, 256, (5, 30, 96, 3), dtype=np.uint8)
        cell = (9, 14) if toned else (20, 64)  # small cells blend almost everywhere
        s = open_stochastic(torus, (41, 133), backend="opencl", device=device, seed=2, cell=cell, format=format)
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
    "stochastic tiling, RGB": _stochastic_check("RGB", False),
    "stochastic tiling, RGB, toned": _stochastic_check("RGB", True),
    "stochastic tiling, BGRA, toned": _stochastic_check("BGRA", True),
    "detail, RGB": _detail_check(3, "RGB"),
    "detail, grey to BGRA": _detail_check(1, "BGRA"),
    "mode lds, float32": _mode_check("lds", {"seed": 3}),
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
    "mode tiles": _mode_check(*_TILES),
    "mode evolve": _mode_check("evolve", {"seed": 3, "jitter": 2.0}, frames=6, max_share=1.0),
    "mode evolve, rate map": _mode_check(
        "evolve",
        {"seed": 3, "rate_sigma": 4.0, "rate_map": np.linspace(0.5, 2, 48 * 64).reshape(48, 64)},
        frames=6,
        max_share=1.0,
    ),
}

#: kernel variant -> the checks that must pass before a device uses it (run after CHECKS)
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

        from .opencl import get_context

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


def _child(expected: DeviceInfo) -> int:
    """Run every check on device ``expected`` and print progress lines and the verdict (JSON)."""
    global ALLOWED_VARIANTS
    import warnings

    warnings.simplefilter("ignore")  # compiler chatter is not a verdict
    index = expected.index
    info = next((d for d in devices() if d.index == index), None)
    if info != expected:
        v = Verdict(False, f"device {index} is not {expected.describe()} in the self-test's process")
        print(f"verdict\t{json.dumps(asdict(v))}", flush=True)
        return 0
    start = time.perf_counter()
    ALLOWED_VARIANTS = frozenset()
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
            ALLOWED_VARIANTS = frozenset({variant})
            if not info.is_cpu:
                v.variants[variant] = False
                v.variant_reasons[variant] = "CPU devices only"
                continue
            problem = _run_one(f"variant {variant}", lambda d, vchecks=vchecks: _all(vchecks, d), index)
            v.variants[variant] = problem is None
            if problem:
                v.variant_reasons[variant] = problem
    if v.ok:
        for engine, measure in SPEED_CASES.items():
            print(f"check\tspeed {engine}", flush=True)
            try:
                v.speed[engine] = round(measure(index), 3)
            except Exception as exc:  # a measurement that fails decides nothing: OpenCL stays
                print(f"fail\tspeed {engine}\t{_one_line(exc)}", flush=True)
            else:
                print(f"pass\tspeed {engine}", flush=True)
    v.seconds = time.perf_counter() - start
    print(f"verdict\t{json.dumps(asdict(v))}", flush=True)
    return 0


def _projection_speed(precision: str, size: tuple[int, int] = (288, 352), n: int = 50, frames: int = 12):
    """OpenCL's frame rate over numpy's for the projection engine (lds, mixture) at ``size``
    (a basis beyond any cache: both are bound by memory there, as at larger sizes), the
    median of alternating rounds."""

    def measure(device: str) -> float:
        import pyopencl as cl

        from .opencl import get_context
        from .projection import open_projector

        h, w = size
        rng = np.random.default_rng(0)
        basis = (rng.standard_normal((n, h * w * 3), dtype=np.float32) * 0.1).astype(precision)
        mean = np.full(h * w * 3, 128, np.float32)
        ctx = get_context(device)
        engines = [
            open_projector(basis, mean, shape=(h, w, 3), channels=3, ctx=c, queue=c and cl.CommandQueue(c))
            for c in (ctx, None)
        ]
        out = np.empty((h, w, 3), np.uint8)
        times: list[list[float]] = [[], []]
        try:
            for r in range(frames + 2):
                for k, e in enumerate(engines):
                    e.coef[:] = rng.standard_normal(e.coef.size)
                    t = time.perf_counter()
                    e.run(out)
                    if r >= 2:  # the first rounds warm caches and threads
                        times[k].append(time.perf_counter() - t)
        finally:
            engines[0].close()
        return float(np.median(times[1]) / np.median(times[0]))

    return measure


#: engine -> measure(device): its OpenCL frame rate over its numpy reference's (Verdict.speed)
SPEED_CASES: dict[str, Callable[[str], float]] = {
    "projection float32": _projection_speed("float32"),
    "projection float16": _projection_speed("float16"),
}


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


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(
            "usage: python -m dynatex.player.selftest DEVICE_JSON  (run by the player, not by hand: "
            "use python -m dynatex.player --check)",
            file=sys.stderr,
        )
        raise SystemExit(2)
    from dynatex.player import selftest as _module  # this file runs as __main__: use the module's globals

    raise SystemExit(_module._child(DeviceInfo(**json.loads(sys.argv[1]))))
