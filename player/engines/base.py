"""The engine layer: what draws a mode's frames, and what the engines share.

A mode (a :class:`~dynatex.player.base.Player`) is a model, a clock and controls; its
frames come from one engine, ``player.engines``, of one of five kinds, each a pair of an
OpenCL engine and its numpy reference behind one interface:

=============  ===========================  ======================================
engine         module                        draws
=============  ===========================  ======================================
projection     :mod:`.projection`           ``mean + coef @ basis`` (lds, mixture)
gather         :mod:`.gather`               stored pixels at per-pixel times (tiles)
stochastic     :mod:`.stochastic`           blended torus windows (tiles above the torus)
runs           :mod:`.runs`                 a quilt's runs at per-block times (evolve)
blend          :mod:`.blend`                weighted sums of stored frames (turnpoints)
=============  ===========================  ======================================

The interface is :class:`dynatex.player.engines.Engine`: built from the model's arrays
(uploaded once; ``ctx`` and ``queue`` are the player's, the buffers the engine's), ``draw``
writes a frame into the caller's array and returns None once it is there or the event after
which it is (so every mode can keep a frame in flight), ``bytes_per_frame`` for roofline
figures, ``backend``, and ``close()``, which the player calls.
:func:`dynatex.player.engines.open_engine` picks the OpenCL engine or the reference, the same
way for every engine.

What the OpenCL engines share lives here: :class:`Kernel` binds arguments by the names
the ``.cl`` file declares, so no index has to mirror a signature.
:class:`FrameOut` owns the frame's destination: where the device shares host memory (a CPU
device, probed once per context) the kernel writes straight into the caller's array,
otherwise into a device buffer copied into it; either way the frame may be left in flight
and its event returned, which is what :meth:`Player.start_frame` hands to the caller.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numpy as np

from ..errors import KernelBuildError
from ..opencl.programs import Program, writes_through

#: caller's arrays whose host-pointer buffers stay wrapped (double buffering needs two)
HELD_ARRAYS = 4


class Kernel:
    """One kernel object of ``program`` with its arguments set by name.

    >>> k = Kernel(build_program(ctx, ("pixels.cl", "projection.cl"), defines), "project")   # doctest: +SKIP
    >>> k.set(coef=d_coef, n=np.int32(12))                             # doctest: +SKIP
    """

    def __init__(self, program: Program, name: str) -> None:
        self.name = name
        self.kernel = program.kernel(name)
        self.args = program.arg_names.get(name, ())
        if len(self.args) != self.kernel.num_args:
            raise KernelBuildError(
                f"kernel {name!r}: {len(self.args)} argument names read from "
                f"{program.filename}, but the kernel takes {self.kernel.num_args}"
            )
        self._index = {arg: i for i, arg in enumerate(self.args)}

    def set(self, **values: Any) -> None:
        """Set the arguments named by the keywords (a buffer, a numpy scalar of the declared type)."""
        for arg, value in values.items():
            try:
                index = self._index[arg]
            except KeyError:
                raise TypeError(
                    f"kernel {self.name!r} has no argument {arg!r} (it has {', '.join(self.args)})"
                ) from None
            self.kernel.set_arg(index, value)

    def launch(self, queue, global_size: tuple[int, ...], local_size: tuple[int, ...] | None = None):
        """Enqueue the kernel with its current arguments; returns the event."""
        import pyopencl as cl

        return cl.enqueue_nd_range_kernel(queue, self.kernel, global_size, local_size)


class FrameOut:
    """Delivers the frames ``kernel`` writes through its argument ``arg`` to callers' arrays.

    ``nbytes`` is the device buffer's size (at least a frame; kernels that write whole
    vectors past the frame's end need ``direct=False``: a caller's array has no slack).
    ``direct=None`` writes straight into callers' arrays where the device shares host
    memory (:func:`writes_through`).
    """

    def __init__(self, ctx, queue, kernel: Kernel, arg: str, nbytes: int, *, direct: bool | None = None) -> None:
        import pyopencl as cl

        self.ctx, self.queue, self.kernel, self.arg = ctx, queue, kernel, arg
        self.direct = writes_through(ctx) if direct is None else bool(direct)
        self.buffer = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, nbytes)
        self._held: OrderedDict[int, tuple[np.ndarray, Any]] = OrderedDict()
        self._bound: Any = None
        self._bind(self.buffer)

    def _bind(self, buffer) -> None:
        if buffer is not self._bound:
            self.kernel.set(**{self.arg: buffer})
            self._bound = buffer

    def _host_buffer(self, out: np.ndarray):
        """The buffer wrapping ``out`` (kept, with ``out`` itself, for the last few arrays)."""
        import pyopencl as cl

        key = id(out)
        held = self._held.get(key)
        if held is not None and held[0] is out:
            self._held.move_to_end(key)
            return held[1]
        buf = cl.Buffer(self.ctx, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=out.reshape(-1))
        self._held[key] = (out, buf)
        while len(self._held) > HELD_ARRAYS:
            self._held.popitem(last=False)
        return buf

    def destination(self, out: np.ndarray | None = None):
        """The buffer the frame ending in ``out`` (None: the device's own) is written to, for a
        kernel that runs before :meth:`launch` on the same frame (an earlier pass)."""
        return self._host_buffer(out) if self.direct and out is not None else self.buffer

    def launch(
        self,
        out: np.ndarray,
        global_size: tuple[int, ...],
        local_size: tuple[int, ...] | None = None,
        *,
        wait: bool = True,
    ):
        """Run the kernel for a frame that ends in ``out`` (C-contiguous uint8).

        Returns None once ``out`` holds the frame (``wait=True``), else the event after which it does.
        """
        import pyopencl as cl

        if self.direct:
            self._bind(self._host_buffer(out))
            event = self.kernel.launch(self.queue, global_size, local_size)
        else:
            self._bind(self.buffer)
            self.kernel.launch(self.queue, global_size, local_size)
            event = cl.enqueue_copy(self.queue, out.reshape(-1), self.buffer, is_blocking=False)
        return finish(event, wait)

    def launch_on_device(self, global_size: tuple[int, ...], local_size: tuple[int, ...] | None = None):
        """Run the kernel into the device buffer alone (the benchmarks' kernel-only time); returns the event."""
        self._bind(self.buffer)
        return self.kernel.launch(self.queue, global_size, local_size)

    def copy_from(self, src, out: np.ndarray, *, offset: int = 0, wait: bool = True):
        """Copy a frame that already lies in device buffer ``src`` at byte ``offset`` into ``out``."""
        import pyopencl as cl

        event = cl.enqueue_copy(self.queue, out.reshape(-1), src, src_offset=offset, is_blocking=False)
        return finish(event, wait)


def context_and_queue(ctx: Any, queue: Any, device: str | None) -> tuple[Any, Any]:
    """The owner's ``ctx`` and ``queue``, or for an engine used on its own (``ctx`` None) the
    context of ``device`` (:func:`~dynatex.player.opencl.context.get_context`) and a new queue."""
    import pyopencl as cl

    from ..opencl.context import get_context

    ctx = get_context(device) if ctx is None else ctx
    return ctx, cl.CommandQueue(ctx) if queue is None else queue


def finish(event, wait: bool):
    """``event`` completed and None when ``wait``, else ``event`` itself."""
    if wait:
        event.wait()
        return None
    return event
