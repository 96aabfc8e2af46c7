"""OpenCL programs: ``player/kernels/*.cl`` built once per context and set of defines, kernels
fetched once per owner, and the host-memory probe the engines' frame outputs rely on.
"""

from __future__ import annotations

import re
import threading
import warnings
from collections.abc import Mapping
from importlib import resources

import numpy as np

from ..errors import KernelBuildError
from .devices import cl, log

_lock = threading.Lock()
_programs: dict[tuple, Program] = {}
_kernel_fetches = 0

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


def kernel_variants() -> tuple[str, ...]:
    """The kernel variants, by name: the files of ``kernels/variants/`` (not portable OpenCL C),
    each used on a device only where the self-test verified it."""
    root = resources.files("dynatex.player.kernels").joinpath("variants")
    return tuple(sorted(item.name[:-3] for item in root.iterdir() if item.name.endswith(".cl")))


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
