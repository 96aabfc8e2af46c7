"""OpenCL plumbing shared by every player: device choice, one context per device,
programs built once from ``player/kernels/*.cl`` and kernels fetched once.
"""
from __future__ import annotations

import logging
import os
import re
import threading
import warnings
from importlib import resources
from typing import Mapping

import numpy as np

try:
    import pyopencl as cl
except ImportError as _exc:  # pragma: no cover - pyopencl is a hard dependency
    cl = None
    _IMPORT_ERROR: Exception | None = _exc
else:
    _IMPORT_ERROR = None

log = logging.getLogger(__name__)

_FIX = "install an OpenCL platform with `pip install 'pyopencl[pocl]'`, or pass backend='numpy'"


class OpenCLUnavailableError(RuntimeError):
    """No usable OpenCL platform or device."""


class KernelBuildError(RuntimeError):
    """An OpenCL program failed to build; the message carries the compiler log."""


_lock = threading.Lock()
_contexts: dict[str, "cl.Context"] = {}
_programs: dict[tuple, "Program"] = {}
_kernel_fetches = 0


def list_devices() -> list[tuple[str, str]]:
    """``(platform name, device name)`` of every OpenCL device, in ``PYOPENCL_CTX`` index order."""
    _require_pyopencl()
    out = []
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return out
    for p in platforms:
        try:
            devices = p.get_devices()
        except cl.Error:
            continue
        out.extend((p.name, d.name) for d in devices)
    return out


def get_context(device: str | None = None) -> "cl.Context":
    """The shared context for ``device``.

    ``device`` is ``None`` (``PYOPENCL_CTX`` if set, else PoCL, else the first device),
    ``"pocl"``, an index ``"P:D"`` (platform, device) or a substring of a device or platform name.
    """
    _require_pyopencl()
    key = device if device is not None else "env:" + os.environ.get("PYOPENCL_CTX", "")
    with _lock:
        ctx = _contexts.get(key)
        if ctx is None:
            ctx = cl.Context([_pick_device(device)])
            _contexts[key] = ctx
        return ctx


def _pick_device(device: str | None) -> "cl.Device":
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:
        raise OpenCLUnavailableError(f"no OpenCL platform found ({exc}); {_FIX}") from None
    pairs = []
    for p in platforms:
        try:
            pairs.extend((p, d) for d in p.get_devices())
        except cl.Error:
            continue
    if not pairs:
        raise OpenCLUnavailableError(f"no OpenCL device found; {_FIX}")
    if device is None:
        env = os.environ.get("PYOPENCL_CTX")
        if env:
            return _match(pairs, platforms, env, "PYOPENCL_CTX")
        pocl = [(p, d) for p, d in pairs if _is_pocl(p)]
        others = [(p, d) for p, d in pairs if not _is_pocl(p)]
        failures = []
        for p, d in pocl + others:
            err = _probe_build(d)
            if err is None:
                return d
            version = re.search(r"PoCL [\w.+-]+", p.version or "")
            failures.append(f"{version.group(0) if version else p.name} / {d.name}: {err}")
        raise OpenCLUnavailableError(
            "no OpenCL device here can compile kernels (" + "; ".join(failures) + "). "
            "PoCL's LLVM may not know this CPU: run ./install.sh (it adds the system PoCL, "
            "`apt-get install pocl-opencl-icd`), or pass backend='numpy'")
    return _match(pairs, platforms, device, "device")


def _is_pocl(platform: "cl.Platform") -> bool:
    return "portable computing language" in platform.name.lower() or "pocl" in platform.vendor.lower()


_PROBE_SOURCE = "__kernel void probe(__global float *a) { a[get_global_id(0)] *= 2.0f; }"


def _probe_build(device: "cl.Device") -> str | None:
    """None when ``device`` compiles a trivial kernel, else the first line of the failure."""
    try:
        ctx = cl.Context([device])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cl.Program(ctx, _PROBE_SOURCE).build()
    except cl.Error as exc:
        lines = [ln.strip() for ln in str(exc).splitlines() if "error" in ln.lower() and ln.strip()]
        return (lines[-1] if lines else str(exc).splitlines()[0])[:160]
    return None


def _match(pairs, platforms, spec: str, what: str) -> "cl.Device":
    spec = spec.strip()
    if spec.lower() == "pocl":
        spec = "portable computing language"
    parts = spec.split(":")
    if all(p.isdigit() for p in parts if p) and parts[0]:
        try:
            plat = platforms[int(parts[0])]
            devs = plat.get_devices()
            return devs[int(parts[1]) if len(parts) > 1 and parts[1] else 0]
        except (IndexError, cl.Error):
            raise OpenCLUnavailableError(f"{what}={spec!r}: no such OpenCL platform/device index") from None
    low = spec.lower()
    for p, d in pairs:
        if low in d.name.lower() or low in p.name.lower():
            return d
    names = "; ".join(f"{p.name}: {d.name}" for p, d in pairs)
    raise OpenCLUnavailableError(f"{what}={spec!r} matches no OpenCL device (available: {names})")


def _require_pyopencl() -> None:
    if cl is None:
        raise OpenCLUnavailableError(f"pyopencl cannot be imported ({_IMPORT_ERROR}); {_FIX}")


_PROBE_WRITE = ("__kernel void probe_write(__global uchar *o) "
                "{ size_t i = get_global_id(0); o[i] = (uchar)(i * 7 + 3); }")
_writes_through: dict[int, bool] = {}


def writes_through(ctx: "cl.Context") -> bool:
    """Whether kernel writes into a ``USE_HOST_PTR`` buffer land in the host array itself,
    with no map or copy (true of CPU devices such as PoCL's). Probed once per context on an
    odd-aligned array, so players can write frames straight into the caller's buffer."""
    key = ctx.int_ptr
    if key not in _writes_through:
        _writes_through[key] = _probe_writes_through(ctx)
    return _writes_through[key]


def _probe_writes_through(ctx: "cl.Context") -> bool:
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


def device_shares_host_memory(ctx: "cl.Context") -> bool:
    dev = ctx.devices[0]
    try:
        return bool(dev.host_unified_memory)
    except cl.Error:
        return dev.type & cl.device_type.CPU != 0


class Program:
    """A ``.cl`` file built once per context and set of defines (see :func:`build_program`)."""

    def __init__(self, ctx: "cl.Context", filename: str, defines: Mapping[str, object]) -> None:
        self.filename = filename
        self.options = [f"-D{k}={_define(v)}" for k, v in sorted(defines.items())]
        source = resources.files("dynatex.player.kernels").joinpath(filename).read_text()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                self.program = cl.Program(ctx, source).build(options=self.options)
            except cl.RuntimeError as exc:
                logtext = str(exc).strip()
                raise KernelBuildError(
                    f"building player/kernels/{filename} with {' '.join(self.options)} failed:\n{logtext}") from None
        for w in caught:
            log.debug("OpenCL compiler output for %s: %s", filename, w.message)

    def kernel(self, name: str) -> "cl.Kernel":
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


def build_program(ctx: "cl.Context", filename: str, defines: Mapping[str, object] | None = None) -> Program:
    """The program ``filename`` built for ``ctx`` with ``defines``; built only the first time."""
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
    """``python -m dynatex.player [--check]``: list devices; with --check exit 1 if none can build."""
    import argparse
    parser = argparse.ArgumentParser(prog="python -m dynatex.player")
    parser.add_argument("--check", action="store_true", help="exit 1 unless a device can compile kernels")
    args = parser.parse_args(argv)
    try:
        for plat, dev in list_devices():
            print(f"{plat}: {dev}")
        ctx = get_context()
    except OpenCLUnavailableError as exc:
        print(f"no usable OpenCL device: {exc}")
        return 1
    d = ctx.devices[0]
    print(f"default device: {d.platform.name} {d.platform.version}: {d.name}")
    if args.check:   # a device named by PYOPENCL_CTX is taken unprobed: probe it here
        err = _probe_build(d)
        if err is not None:
            print(f"the default device cannot compile kernels: {err}")
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
