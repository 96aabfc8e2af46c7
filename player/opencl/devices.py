"""OpenCL plumbing shared by every player: device choice (only devices that passed the
self-test, :mod:`dynatex.player.selftest`), one context per device, programs built once
from ``player/kernels/*.cl`` and kernels fetched once.
"""

from __future__ import annotations

import logging
import os
import re
import threading
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources

import numpy as np

from .errors import DeviceNotVerifiedError, KernelBuildError, OpenCLUnavailableError

try:
    import pyopencl as cl
except ImportError as _exc:  # pragma: no cover - pyopencl is a hard dependency
    cl = None
    _IMPORT_ERROR: Exception | None = _exc
else:
    _IMPORT_ERROR = None

log = logging.getLogger(__name__)

#: the numpy backend, as the API and the command line spell it
_NUMPY = "use the numpy backend (backend='numpy'; dynatex --backend numpy)"
_FIX = f"install an OpenCL platform (./install.sh, or `apt-get install pocl-opencl-icd`), or {_NUMPY}"


_lock = threading.Lock()
_contexts: dict[str, cl.Context] = {}
_programs: dict[tuple, Program] = {}
_infos: dict[int, DeviceInfo] = {}  # device handle -> its DeviceInfo, for get_context's devices
_kernel_fetches = 0


@dataclass(frozen=True)
class DeviceInfo:
    """What identifies one OpenCL device: its ``P:D`` index and the names its verdict is cached by."""

    index: str
    platform: str
    platform_version: str
    name: str
    vendor: str
    driver_version: str
    is_cpu: bool

    @property
    def is_pocl(self) -> bool:
        return "portable computing language" in self.platform.lower() or "pocl" in self.platform_version.lower()

    def describe(self) -> str:
        """One line: platform, version, device."""
        return f"{self.platform} ({' '.join(self.platform_version.split()[:4])}) / {self.name}"


def devices() -> list[DeviceInfo]:
    """Every OpenCL device present, in ``PYOPENCL_CTX`` index order (none without OpenCL)."""
    _require_pyopencl()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    out = []
    for i, p in enumerate(platforms):
        try:
            devs = p.get_devices()
        except cl.Error:
            continue
        for j, d in enumerate(devs):
            out.append(
                DeviceInfo(
                    f"{i}:{j}",
                    p.name.strip(),
                    p.version.strip(),
                    d.name.strip(),
                    d.vendor.strip(),
                    d.driver_version.strip(),
                    bool(d.type & cl.device_type.CPU),
                )
            )
    return out


def list_devices() -> list[tuple[str, str]]:
    """``(platform name, device name)`` of every OpenCL device, in ``PYOPENCL_CTX`` index order."""
    return [(d.platform, d.name) for d in devices()]


def device_info(device: cl.Device) -> DeviceInfo:
    """The :class:`DeviceInfo` of a pyopencl device (known for the devices of
    :func:`get_context`'s contexts, else found among :func:`devices`)."""
    info = _infos.get(device.int_ptr)
    if info is not None:
        return info
    for info in devices():
        if (info.platform, info.platform_version, info.name, info.driver_version) == (
            device.platform.name.strip(),
            device.platform.version.strip(),
            device.name.strip(),
            device.driver_version.strip(),
        ):
            return info
    raise OpenCLUnavailableError(f"device {device.name!r} is not among this process's OpenCL devices")


def preference_order(infos: list[DeviceInfo]) -> list[DeviceInfo]:
    """The order devices are tried in: PoCL first (newest version first), then the others as listed."""

    def pocl_version(info: DeviceInfo) -> tuple[int, ...]:
        m = re.search(r"PoCL (\d+)\.(\d+)", info.platform_version)
        return tuple(int(v) for v in m.groups()) if m else (0, 0)

    pocl = sorted((d for d in infos if d.is_pocl), key=pocl_version, reverse=True)
    return pocl + [d for d in infos if not d.is_pocl]


def get_context(device: str | None = None) -> cl.Context:
    """The shared context for a verified ``device``.

    ``device`` is ``None`` (``PYOPENCL_CTX`` if set, else the first device that passes the
    self-test, PoCL first), ``"pocl"``, an index ``"P:D"`` (platform, device) or a substring
    of a device or platform name. A device named here or by ``PYOPENCL_CTX`` that fails the
    self-test raises :class:`DeviceNotVerifiedError` saying why; no verified device at all
    raises :class:`OpenCLUnavailableError` listing each device's failure.
    """
    _require_pyopencl()
    key = device if device is not None else "env:" + os.environ.get("PYOPENCL_CTX", "")
    with _lock:
        ctx = _contexts.get(key)
    if ctx is not None:
        return ctx
    info = _pick_device(device)
    with _lock:
        ctx = _contexts.get(key)
        if ctx is None:
            ctx = _contexts.get(info.index)
        if ctx is None:
            ctx = cl.Context([_cl_device(info)])
            _contexts[info.index] = ctx
            _infos[ctx.devices[0].int_ptr] = info
        _contexts[key] = ctx
        return ctx


def _cl_device(info: DeviceInfo) -> cl.Device:
    p, d = (int(v) for v in info.index.split(":"))
    return cl.get_platforms()[p].get_devices()[d]


def _pick_device(device: str | None) -> DeviceInfo:
    from . import selftest

    infos = devices()
    if not infos:
        raise OpenCLUnavailableError(f"no OpenCL device found; {_FIX}")
    spec, what = device, "device"
    if spec is None and os.environ.get("PYOPENCL_CTX"):
        spec, what = os.environ["PYOPENCL_CTX"], "PYOPENCL_CTX"
    if selftest.ALLOWED_VARIANTS is not None:  # the self-test's own child process
        if device is None:
            raise OpenCLUnavailableError("inside the self-test every context names its device")
        return _match(infos, device, "device")
    if spec is not None:
        info = _match(infos, spec, what)
        verdict = selftest.verdict(info)
        if not verdict.ok:
            raise DeviceNotVerifiedError(f"{what}={spec!r}: {info.describe()} failed the self-test: {verdict.reason}")
        return info
    failures = []
    for info in preference_order(infos):
        verdict = selftest.verdict(info)
        if verdict.ok:
            return info
        failures.append(f"{info.describe()}: {verdict.reason}")
    raise OpenCLUnavailableError(
        "no OpenCL device here passed the self-test (" + "; ".join(failures) + "). "
        f"Run ./install.sh (it adds the system PoCL, `apt-get install pocl-opencl-icd`), or {_NUMPY}"
    )


def variant_verified(device: cl.Device, variant: str) -> bool:
    """Whether kernel ``variant`` (a file of ``kernels/variants/``) passed the self-test on
    ``device``: its cached verdict says so (no verdict, no variant; nothing is run here)."""
    from . import selftest

    if selftest.ALLOWED_VARIANTS is not None:  # inside the self-test itself
        return variant in selftest.ALLOWED_VARIANTS
    try:
        verdict = selftest.cached_verdict(device_info(device))
    except OpenCLUnavailableError:
        return False
    return bool(verdict and verdict.ok and verdict.variants.get(variant, False))


def engine_speed(device: cl.Device, engine: str) -> float | None:
    """``engine``'s OpenCL frame rate over its numpy reference's on ``device``, as the self-test
    measured it (:data:`dynatex.player.selftest.SPEED_CASES`); None when not measured."""
    from . import selftest

    if selftest.ALLOWED_VARIANTS is not None:  # inside the self-test itself
        return None
    try:
        verdict = selftest.cached_verdict(device_info(device))
    except OpenCLUnavailableError:
        return None
    return verdict.speed.get(engine) if verdict and verdict.ok else None


def _match(infos: list[DeviceInfo], spec: str, what: str) -> DeviceInfo:
    spec = spec.strip()
    low = "portable computing language" if spec.lower() == "pocl" else spec.lower()
    parts = spec.split(":")
    if parts[0].isdigit() and all(p.isdigit() for p in parts[1:] if p) and len(parts) <= 2:
        index = f"{int(parts[0])}:{int(parts[1]) if len(parts) > 1 and parts[1] else 0}"
        for info in infos:
            if info.index == index:
                return info
        raise OpenCLUnavailableError(
            f"{what}={spec!r}: no such OpenCL platform/device index (available: {', '.join(d.index for d in infos)})"
        )
    matches = [d for d in infos if low in d.name.lower() or low in d.platform.lower()]
    if matches:
        return preference_order(matches)[0]
    names = "; ".join(f"{d.index} {d.platform}: {d.name}" for d in infos)
    raise OpenCLUnavailableError(f"{what}={spec!r} matches no OpenCL device (available: {names})")


def _require_pyopencl() -> None:
    if cl is None:
        raise OpenCLUnavailableError(f"pyopencl cannot be imported ({_IMPORT_ERROR}); {_FIX}")


_PROBE_WRITE = (
    "__kernel void probe_write(__global uchar *o) { size_t i = get_global_id(0); o[i] = (uchar)(i * 7 + 3); }"
)
_writes_through: dict[int, bool] = {}


def writes_through(ctx: cl.Context) -> bool:
    """Whether kernel writes into a ``USE_HOST_PTR`` buffer land in the host array itself,
    with no map or copy (true of CPU devices such as PoCL's). Probed once per context on an
    odd-aligned array, so players can write frames straight into the caller's buffer."""
    key = ctx.int_ptr
    if key not in _writes_through:
        _writes_through[key] = _probe_writes_through(ctx)
    return _writes_through[key]


def _probe_writes_through(ctx: cl.Context) -> bool:
    if not device_shares_host_memory(ctx):
        return False
    try:
        queue = cl.CommandQueue(ctx)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            kernel = cl.Kernel(cl.Program(ctx, _PROBE_WRITE).build(), "probe_write")
        base = np.zeros(4096 + 3, np.uint8)
        host = base[3:]
        buf = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=host)
        kernel.set_args(buf)
        cl.enqueue_nd_range_kernel(queue, kernel, (host.size,), None)
        queue.finish()
    except cl.Error:
        return False
    return bool((host == ((np.arange(host.size) * 7 + 3) & 255).astype(np.uint8)).all())


def device_shares_host_memory(ctx: cl.Context) -> bool:
    dev = ctx.devices[0]
    try:
        return bool(dev.host_unified_memory)
    except cl.Error:
        return dev.type & cl.device_type.CPU != 0


def kernel_source(filename: str | tuple[str, ...]) -> str:
    """The text of ``kernels/filename``; a tuple of names is their texts one after another."""
    names = (filename,) if isinstance(filename, str) else filename
    root = resources.files("dynatex.player.kernels")
    return "\n".join(root.joinpath(name).read_text() for name in names)


_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)
_MACRO = re.compile(r"^[ \t]*#[ \t]*define[ \t]+(\w+)[ \t]+((?:[^\n]*\\\n)*[^\n]*)", re.M)
_KERNEL = re.compile(r"__kernel\s+void\s+(\w+)\s*\(([^)]*)\)")


def kernel_arg_names(source: str) -> dict[str, tuple[str, ...]]:
    """Each ``__kernel``'s argument names in ``source``; a parameter list may be one
    object-like macro (``GATHER_PARAMS``), which is expanded. (Drivers report names only for
    programs built from source with ``-cl-kernel-arg-info``, not for cached binaries.)"""
    text = _COMMENT.sub(" ", source)
    macros = {m.group(1): m.group(2).replace("\\\n", " ") for m in _MACRO.finditer(text)}
    out = {}
    for m in _KERNEL.finditer(text):
        params = macros.get(m.group(2).strip(), m.group(2))
        out[m.group(1)] = tuple(p.split()[-1].lstrip("*") for p in params.split(",") if p.strip())
    return out


class Program:
    """``.cl`` files built once per context and set of defines (see :func:`build_program`)."""

    def __init__(self, ctx: cl.Context, filename: str | tuple[str, ...], defines: Mapping[str, object]) -> None:
        self.filename = filename if isinstance(filename, str) else " + ".join(filename)
        # -w: a compiler that prints its warnings to the process's stderr (PoCL's clang does, on
        # the x86 variant's wide vectors) must not write into a game's console
        self.options = [f"-D{k}={_define(v)}" for k, v in sorted(defines.items())] + ["-w"]
        source = kernel_source(filename)
        #: kernel name -> its argument names, as the source declares them (engine.Kernel sets arguments by name)
        self.arg_names = kernel_arg_names(source)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                self.program = cl.Program(ctx, source).build(options=self.options)
            except cl.RuntimeError as exc:
                logtext = str(exc).strip()
                raise KernelBuildError(
                    f"building player/kernels/{self.filename} with {' '.join(self.options)} failed:\n{logtext}"
                ) from None
        for w in caught:
            log.debug("OpenCL compiler output for %s: %s", filename, w.message)

    def kernel(self, name: str) -> cl.Kernel:
        """A new kernel object for ``name``, with its own arguments.

        Fetch it once per owner (a player, at open) and reuse it for every launch: kernel
        arguments live in the kernel object, so two players must not share one.
        """
        global _kernel_fetches
        try:
            k = cl.Kernel(self.program, name)
        except cl.Error as exc:
            raise KernelBuildError(f"player/kernels/{self.filename} has no kernel {name!r} ({exc})") from None
        _kernel_fetches += 1
        return k


def build_program(
    ctx: cl.Context, filename: str | tuple[str, ...], defines: Mapping[str, object] | None = None
) -> Program:
    """The program ``filename`` (or several files, in order) built for ``ctx`` with ``defines``;
    built only the first time."""
    defines = dict(defines or {})
    key = (ctx.int_ptr, filename, tuple(sorted((k, _define(v)) for k, v in defines.items())))
    with _lock:
        prog = _programs.get(key)
        if prog is None:
            prog = _programs[key] = Program(ctx, filename, defines)
        return prog


def build_count() -> tuple[int, int]:
    """``(programs built, kernels fetched)`` in this process; tests use it to prove reuse."""
    return len(_programs), _kernel_fetches


def _define(v: object) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, (float, np.floating)):
        return repr(float(v)) + "f"
    return str(v)


def _main(argv: list[str] | None = None) -> int:
    """``python -m dynatex.player [--check] [--refresh]``: the devices, their self-test verdicts
    and the one the player uses; with --check exit 1 when no device passed."""
    import argparse

    from . import selftest

    parser = argparse.ArgumentParser(
        prog="python -m dynatex.player", description="List the OpenCL devices and their self-test verdicts."
    )
    parser.add_argument(
        "--check", action="store_true", help="self-test every device (cached) and exit 1 unless one passed"
    )
    parser.add_argument("--refresh", action="store_true", help="run the self-tests again, ignoring cached verdicts")
    args = parser.parse_args(argv)
    try:
        infos = devices()
    except OpenCLUnavailableError as exc:
        print(f"no usable OpenCL: {exc}")
        return 1
    if not infos:
        print(f"no OpenCL device found; {_FIX}")
        return 1
    passed = []
    for info in preference_order(infos):
        if args.check or args.refresh:
            v = selftest.verdict(info, refresh=args.refresh)
        else:
            v = selftest.cached_verdict(info)
        if v is None:
            state = "not yet verified (--check runs the self-test)"
        elif v.ok:
            variants = ", ".join(f"{k} {'ok' if ok else 'not used'}" for k, ok in sorted(v.variants.items()))
            speed = ", ".join(
                f"{k} {x:.2f}x numpy ({'OpenCL' if x >= 1 else 'numpy'} under auto)" for k, x in sorted(v.speed.items())
            )
            state = f"verified ({v.seconds:.1f} s{'; ' + variants if variants else ''}{'; ' + speed if speed else ''})"
            passed.append(info)
        else:
            state = f"FAILED: {v.reason}"
        print(f"{info.index}  {info.describe()}, driver {info.driver_version}: {state}")
    if args.check or args.refresh:
        if not passed:
            print("no OpenCL device passed the self-test; the player's numpy backend works without one")
            return 1
        print(f"the player uses {passed[0].index} {passed[0].describe()}")
    print(f"verdicts cached in {selftest.cache_path()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
