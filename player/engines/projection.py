"""The projection ``frame = mean + sum_i coef_i * basis[i]`` to uint8, shared by the modes
whose frames are a linear combination of stored rows (``lds``, ``mixture``).

OpenCL (:class:`ProjectorOpenCL`): kernel ``project`` of ``kernels/projection.cl`` over a blocked
copy of the basis (for each block of ``BLOCK`` values, its ``n x BLOCK`` sub-matrix is
contiguous), built once and with its arguments set once; per frame one small upload of the
coefficients and one launch into the caller's array (or a device buffer copied into it).
numpy: :class:`ProjectorReference`. :func:`open_projector` picks one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..pixels import pixel_format

BLOCK = 16
#: Work-group size: left to choose, PoCL may make few large groups that leave a core idle
#: (CHANGELOG.md has the measurement).
LOCAL = 32


def blocked_basis(basis: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """``(n, P)`` -> ``(ceil(P / block), n, block)``, zero-padded: the kernel's streaming layout."""
    n, p = basis.shape
    blocks = -(-p // block)
    out = np.zeros((blocks, n, block), basis.dtype)
    full = p // block
    out[:full] = basis[:, : full * block].reshape(n, full, block).transpose(1, 0, 2)
    if blocks != full:
        out[full, :, : p - full * block] = basis[:, full * block :]
    return out


class Projector:
    """Projects coefficient vectors through a fixed basis into ``(H, W, 3)`` uint8 frames.

    The interface of both projection engines (:func:`open_projector` picks one). The
    coefficients are written into :attr:`coef` (float32, length ``max(n, 1)``) and
    :meth:`run` projects them.

    Parameters
    ----------
    basis : (n, P) float32 or float16
        Rows to combine; ``P = H * W * channels``. float16 halves the bytes read per frame.
    mean : (P,) float32
        Added to every frame.
    shape : (H, W, bytes)
        Output frame shape (``bytes`` those of a pixel of ``format``).
    channels : {1, 3}
        Values per pixel in ``basis``; grey frames are replicated to RGB.
    format : {"RGB", "RGBA", "BGRA"}
        Output pixel format (:data:`~dynatex.player.pixels.FORMATS`).
    """

    backend = ""

    def __init__(
        self, basis: np.ndarray, mean: np.ndarray, *, shape: tuple[int, int, int], channels: int, format: str = "RGB"
    ) -> None:
        self.format = pixel_format(format)
        self.n, self.values = basis.shape
        self.shape = tuple(shape)
        self.channels = channels
        self.half = basis.dtype == np.float16
        self.basis_bytes = basis.nbytes
        self.coef = np.zeros(max(self.n, 1), np.float32)

    @property
    def bytes_per_frame(self) -> int:
        """The basis and mean read, plus the uint8 frame written."""
        return int(self.basis_bytes + 4 * self.values + int(np.prod(self.shape)))

    def run(self, out: np.ndarray, *, wait: bool = True):
        """Project :attr:`coef` into ``out`` ((H, W, 3) uint8, C-contiguous).

        Returns None once ``out`` holds the frame, or (``wait=False``, OpenCL) the event after
        which it does. :attr:`coef` may be changed as soon as this returns.
        """
        raise NotImplementedError

    def draw(self, out: np.ndarray, *, wait: bool = True):
        """:meth:`run`, in the words of every engine (:class:`~dynatex.player.engines.Engine`)."""
        return self.run(out, wait=wait)

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for the reference)."""


class ProjectorReference(Projector):
    """The numpy reference: ``coef @ basis + mean``, rounded and saturated, in float32."""

    backend = "numpy"

    def __init__(
        self, basis: np.ndarray, mean: np.ndarray, *, shape: tuple[int, int, int], channels: int, format: str = "RGB"
    ) -> None:
        super().__init__(basis, mean, shape=shape, channels=channels, format=format)
        self._basis = basis.astype(np.float32) if self.half else basis
        self._mean = mean

    def run(self, out: np.ndarray, *, wait: bool = True):
        frame = self.coef[: self.n] @ self._basis
        frame += self._mean
        np.rint(frame, out=frame)
        np.clip(frame, 0, 255, out=frame)
        h, w = self.shape[:2]
        if self.format.name == "RGB":
            out[...] = frame.reshape(h, w, self.channels)
        else:
            self.format.from_rgb(np.broadcast_to(frame.reshape(h, w, self.channels), (h, w, 3)), out)


class ProjectorOpenCL(Projector):
    """Kernel ``project`` of ``kernels/projection.cl`` over a blocked copy of the basis (module docstring).

    ``ctx`` and ``queue`` belong to the caller (the mode's player); the engine owns its buffers.
    """

    backend = "opencl"

    def __init__(
        self,
        basis: np.ndarray,
        mean: np.ndarray,
        *,
        shape: tuple[int, int, int],
        channels: int,
        ctx: Any,
        queue: Any,
        format: str = "RGB",
    ) -> None:
        super().__init__(basis, mean, shape=shape, channels=channels, format=format)
        import pyopencl as cl

        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel

        self.queue = queue
        blocked = blocked_basis(basis)
        blocks = blocked.shape[0]
        padded = blocks * BLOCK
        mean_p = np.zeros(padded, np.float32)
        mean_p[: self.values] = mean
        mf = cl.mem_flags
        self._d_basis = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=blocked)
        del blocked
        self._d_mean = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=mean_p)
        self._d_coef = cl.Buffer(ctx, mf.READ_ONLY, self.coef.nbytes)
        prog = build_program(
            ctx, "projection.cl", {"BLOCK": BLOCK, "HALF": self.half, "CHANNELS": channels, **self.format.defines}
        )
        self._kernel = Kernel(prog, "project")
        self._kernel.set(
            basis=self._d_basis, mean=self._d_mean, coef=self._d_coef, n=np.int32(self.n), values=np.int32(self.values)
        )
        #: the kernel's frame destination (writes straight into callers' arrays where the device shares host memory)
        pixels = self.values // channels
        self.out = FrameOut(ctx, queue, self._kernel, "out", max(padded * (3 // channels), pixels * self.format.bytes))
        self._gsize = (-(-blocks // LOCAL) * LOCAL,)
        self._lsize = (LOCAL,)

    @property
    def direct(self) -> bool:
        """Frames are written straight into the caller's array (no copy)."""
        return self.out.direct

    def run(self, out: np.ndarray, *, wait: bool = True):
        import pyopencl as cl

        cl.enqueue_copy(self.queue, self._d_coef, self.coef, is_blocking=not wait)
        return self.out.launch(out, self._gsize, self._lsize, wait=wait)

    def run_on_device(self):
        """Project :attr:`coef` into the device frame ``out.buffer`` alone (a later pass reads it); the event."""
        import pyopencl as cl

        cl.enqueue_copy(self.queue, self._d_coef, self.coef, is_blocking=False)
        return self.out.launch_on_device(self._gsize, self._lsize)

    def close(self) -> None:
        self.queue.finish()
        for name in ("_d_basis", "_d_mean", "_d_coef"):
            buf = self.__dict__.pop(name, None)
            if buf is not None:
                buf.release()


def open_projector(
    basis: np.ndarray,
    mean: np.ndarray,
    *,
    shape: tuple[int, int, int],
    channels: int,
    ctx: Any = None,
    queue: Any = None,
    format: str = "RGB",
) -> Projector:
    """The OpenCL projection engine on ``ctx``/``queue``, or the numpy reference when ``ctx`` is None."""
    if ctx is None:
        return ProjectorReference(basis, mean, shape=shape, channels=channels, format=format)
    return ProjectorOpenCL(basis, mean, shape=shape, channels=channels, ctx=ctx, queue=queue, format=format)
