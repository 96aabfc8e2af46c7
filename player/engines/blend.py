"""The blend engine: frames that are stored frames or weighted sums of up to four of them.

``out = (sum_k w_k F[i_k] + 128) >> 8`` with integer weights ``w_k`` summing to 256, exact
on both backends (``kernels/blend.cl``; the numpy reference below computes the same
integers). One term is a plain copy of a stored frame. Mode ``turnpoints`` plays through it
(fractional speeds blend two frames, crossfades at jumps up to four).

Examples
--------
>>> import numpy as np
>>> frames = np.stack([np.full((2, 2, 3), v, np.uint8) for v in (0, 100, 200)])
>>> b = open_blend(frames)                              # the numpy reference
>>> out = np.empty((2, 2, 3), np.uint8)
>>> _ = b.render(((1, 128), (2, 128)), out)
>>> int(out[0, 0, 0])
150
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import InvalidArgumentError
from ..pixels import pixel_format

VEC = 16
ITEMS = 4  # uchar16 per work-item of the blend kernels
MAX_TERMS = 4
PIXELS_PER_ITEM = 16  # of the four-byte kernels


class Blend:
    """Weighted sums of the frames of a stack ``(T, H, W, 3)`` uint8, into callers' arrays.

    The interface of both blend engines (:func:`open_blend` picks one): :meth:`render`
    takes ``((frame, weight), ...)`` with 1 to 4 terms, frames in the stack and weights in
    256ths summing to 256, checked before anything reads a frame. Frames come out in the pixel
    ``format`` (:data:`~dynatex.player.pixels.FORMATS`): the reference keeps its stack in it
    (alpha 255 blends to 255, so every byte blends alike), the OpenCL engine keeps RGB and
    places each pixel's bytes as it stores them.
    """

    backend = ""

    def __init__(self, frames: np.ndarray, *, format: str = "RGB") -> None:
        frames = np.asarray(frames)
        if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[3] != 3 or frames.shape[0] < 1:
            raise InvalidArgumentError(
                f"frames must be uint8 (T, H, W, 3) with T >= 1, not {frames.dtype} {frames.shape}"
            )
        self.format = pixel_format(format)
        self.n_frames = int(frames.shape[0])
        self.shape = (int(frames.shape[1]), int(frames.shape[2]), self.format.bytes)
        self.frame_bytes = int(np.prod(self.shape))
        #: bytes the stack occupies where the engine keeps it
        self.memory_bytes = 0

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a one-term frame moves: one stored frame read, the output written."""
        return 2 * self.frame_bytes

    def render(self, sources: tuple[tuple[int, int], ...], out: np.ndarray, *, wait: bool = True):
        """``out`` = the blend of ``sources``; None once it is there, or (``wait=False``) the
        event after which it is."""
        if not 1 <= len(sources) <= MAX_TERMS:
            raise InvalidArgumentError(f"a blend takes 1 to {MAX_TERMS} sources, not {len(sources)}")
        total = 0
        for frame, weight in sources:
            if not 0 <= frame < self.n_frames or weight < 0:
                raise InvalidArgumentError(
                    f"blend source ({frame}, {weight}) names no frame of {self.n_frames} or a negative weight"
                )
            total += weight
        if total != 256:
            raise InvalidArgumentError(f"blend weights must sum to 256, not {total}")
        return self._render(sources, out, wait)

    def _render(self, sources: tuple[tuple[int, int], ...], out: np.ndarray, wait: bool):
        raise NotImplementedError

    def draw(self, out: np.ndarray, sources: tuple[tuple[int, int], ...], *, wait: bool = True):
        """:meth:`render`, in the words of every engine (:class:`~dynatex.player.engines.Engine`)."""
        return self.render(sources, out, wait=wait)

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for the reference)."""


class BlendReference(Blend):
    """The numpy reference (:func:`blend_reference`) over the stack in host memory."""

    backend = "numpy"

    def __init__(self, frames: np.ndarray, *, format: str = "RGB") -> None:
        super().__init__(frames, format=format)
        self._frames = self.format.from_rgb(np.asarray(frames))
        self.memory_bytes = int(self._frames.nbytes)

    def _render(self, sources, out, wait):
        blend_reference(self._frames, sources, out)


class BlendOpenCL(Blend):
    """Kernels ``blend1``/``blend2``/``blend4`` of ``kernels/blend.cl`` over the stack, put on the device once.

    The stack stays RGB on the device whatever the format: four-byte formats (RGBA, BGRA) read
    3/4 of their bytes and are spread to the output's pixels as the kernel stores them. Frames
    go straight into the caller's array where the device shares host memory; an RGB one-term
    frame is a plain copy. ``ctx`` and ``queue`` belong to the caller (the mode's player); the
    engine owns its buffers.
    """

    backend = "opencl"

    def __init__(self, frames: np.ndarray, *, ctx: Any, queue: Any, format: str = "RGB") -> None:
        super().__init__(frames, format=format)
        import pyopencl as cl

        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel

        frames = np.asarray(frames)
        h, w = self.shape[:2]
        rgb_bytes = h * w * 3
        self._vecs = -(-rgb_bytes // (VEC * ITEMS)) * ITEMS
        self.memory_bytes = self.n_frames * self._vecs * VEC
        padded = np.zeros((self.n_frames, self._vecs * VEC), np.uint8)  # every frame padded to whole work-items
        padded[:, :rgb_bytes] = frames.reshape(self.n_frames, -1)
        mf = cl.mem_flags
        self._d_frames = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=padded)
        del padded
        self._d_params = cl.Buffer(ctx, mf.READ_ONLY, 2 * MAX_TERMS * 4)
        defines = {"FRAME_VECS": self._vecs, "ITEMS": ITEMS, "PIXELS": h * w, **self.format.defines}
        prog = build_program(ctx, ("pixels.cl", "blend.cl"), defines)
        self._outs = {}
        rgb = self.format.bytes == 3
        for terms in (2, 4) if rgb else (1, 2, 4):
            kernel = Kernel(prog, f"blend{terms}")
            kernel.set(frames=self._d_frames, **({} if terms == 1 else {"params": self._d_params}))
            self._outs[terms] = FrameOut(ctx, queue, kernel, "out", self.frame_bytes)
        self._gsize = (self._vecs // ITEMS,) if rgb else (-(-h * w // PIXELS_PER_ITEM),)
        #: the kernel a frame of n terms takes: the smallest that has room for them
        self._for_terms = {n: self._outs[min(k for k in self._outs if k >= n)] for n in range(2, MAX_TERMS + 1)}
        self._queue = queue
        self._upload = None

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a one-term frame moves: one stored RGB frame read, the output written."""
        return self.shape[0] * self.shape[1] * 3 + self.frame_bytes

    def _render(self, sources, out, wait):
        import pyopencl as cl

        if len(sources) == 1:
            if self.format.bytes == 3:
                return self._outs[2].copy_from(self._d_frames, out, offset=sources[0][0] * self._vecs * VEC, wait=wait)
            self._outs[1].kernel.set(first=np.int32(sources[0][0]))
            return self._outs[1].launch(out, self._gsize, wait=wait)
        params = np.zeros(2 * MAX_TERMS, np.int32)  # a new array per frame: the last upload may still wait
        for k, (frame, w) in enumerate(sources):
            params[k], params[MAX_TERMS + k] = frame, w
        # the event is kept: dropping it would wait for the copy (and the frame queued before it)
        self._upload = cl.enqueue_copy(self._queue, self._d_params, params, is_blocking=False)
        return self._for_terms[len(sources)].launch(out, self._gsize, wait=wait)

    def close(self) -> None:
        self._queue.finish()
        for name in ("_d_frames", "_d_params"):
            buf = self.__dict__.pop(name, None)
            if buf is not None:
                buf.release()


def open_blend(frames: np.ndarray, *, ctx: Any = None, queue: Any = None, format: str = "RGB") -> Blend:
    """The OpenCL blend engine on ``ctx``/``queue``, or the numpy reference when ``ctx`` is None;
    frames written in pixel ``format``."""
    if ctx is None:
        return BlendReference(frames, format=format)
    return BlendOpenCL(frames, ctx=ctx, queue=queue, format=format)


def blend_reference(frames: np.ndarray, sources: tuple[tuple[int, int], ...], out: np.ndarray) -> np.ndarray:
    """The numpy reference of :meth:`Blend.render`: exact integers, one term a copy."""
    if len(sources) == 1:
        out[...] = frames[sources[0][0]]
        return out
    acc = np.full(frames.shape[1:], 128, np.uint16)
    for frame, w in sources:
        acc += frames[frame].astype(np.uint16) * np.uint16(w)
    np.right_shift(acc, 8, out=acc)
    out[...] = acc
    return out
