"""Motion-compensated crossfades: two stored frames warped toward each other along their stored
flow, then blended (the ``flow`` part of a ``turnpoints`` model).

A crossfade of frames ``a`` and ``b`` with weights ``wa + wb = 256`` (``alpha = wb / 256``) whose
pair has a stored midpoint flow ``f`` (``a(p - f/2)`` matches ``b(p + f/2)``) draws

    out(p) = (wa * a(p - alpha f) + wb * b(p + (1 - alpha) f)) / 256

so a moving object slides from where ``a`` shows it to where ``b`` does instead of fading out
in one place and in at another. Exact integers on both backends (``kernels/warp.cl``; the flow
interpolated bilinearly from its grid in 1/16 pixels, the frames sampled bilinearly in 16ths,
edge pixels repeated), so :func:`warp_reference` gives identical bytes. Any other blend (one
term, three or four, a pair without a stored flow) goes to the blend engine unchanged.

Examples
--------
>>> import numpy as np
>>> from dynatex.tiledb.turnpoints import FlowModel, flow_grid
>>> frames = np.zeros((2, 4, 8, 3), np.uint8)
>>> frames[0, :, 2] = frames[1, :, 4] = 200                 # a bar moving 2 pixels to the right
>>> grid = np.zeros(flow_grid(4, 8, 4) + (2,), np.int16)
>>> grid[..., 0] = 2 * 16                                   # the flow: +2 px in x, in 1/16 px
>>> out = np.empty((4, 8, 3), np.uint8)
>>> _ = warp_reference(frames, 0, 1, 128, 128, grid, 4, out)
>>> out[0, :, 0].tolist()                                   # one bar half-way, not two half-bright
[0, 0, 0, 200, 0, 0, 0, 0]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import InvalidArgumentError
from ...tiledb.turnpoints import FLOW_FRACTION_BITS, FlowModel, flow_grid
from .blend import Blend, BlendOpenCL, BlendReference


class WarpBlend:
    """A blend engine whose two-term blends of a pair with a stored flow are motion-compensated.

    Wraps ``blend`` (:func:`~dynatex.player.engines.blend.open_blend`, either backend) and offers its
    interface (:meth:`render`, ``memory_bytes``, ``bytes_per_frame``, :meth:`close`). The flows are
    put where the blend keeps its frames (on its device for OpenCL). ``warped`` counts the
    frames drawn warped.
    """

    def __init__(self, blend: Blend, flow: FlowModel, *, ctx: Any = None, queue: Any = None) -> None:
        h, w, ch = blend.shape
        self.blend = blend
        self.backend = blend.backend
        self.step_log2 = int(flow.step).bit_length() - 1
        grid = flow_grid(h, w, int(flow.step))
        flows = np.ascontiguousarray(flow.flows, np.int16)
        if flows.shape[1:] != grid + (2,) or 1 << self.step_log2 != flow.step:
            raise InvalidArgumentError(f"flows of shape {flows.shape} do not fit frames of {h}x{w} at step {flow.step}")
        pairs = np.asarray(flow.pairs, np.int64).reshape(-1, 2)
        if pairs.size and (pairs.min() < 0 or pairs.max() >= blend.n_frames):
            raise InvalidArgumentError(f"flow pairs name frames outside 0..{blend.n_frames - 1}")
        #: (a, b) -> (index of the flow, sign): the flow from a toward b is sign * flows[index]
        self.pairs: dict[tuple[int, int], tuple[int, int]] = {}
        for k, (a, b) in enumerate(pairs.tolist()):
            self.pairs[(a, b)] = (k, 1)
            self.pairs[(b, a)] = (k, -1)
        self.warped = 0
        self._flows = flows
        self._cl = None
        if isinstance(blend, BlendOpenCL):
            self._cl = _WarpOpenCL(blend, flows, self.step_log2, grid, ctx, queue)
        elif not isinstance(blend, BlendReference):
            raise InvalidArgumentError(f"no warp for a {type(blend).__name__}")
        self.memory_bytes = blend.memory_bytes + int(flows.nbytes)

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a one-term frame moves (as the blend engine's)."""
        return self.blend.bytes_per_frame

    def render(self, sources: tuple[tuple[int, int], ...], out: np.ndarray, *, wait: bool = True):
        """``out`` = the blend of ``sources``, warped where it is a pair with a stored flow; None
        once it is there, or (``wait=False``) the event after which it is."""
        hit = self.pairs.get((sources[0][0], sources[1][0])) if len(sources) == 2 else None
        if hit is None or sources[0][1] == 256 or sources[1][1] == 256:
            return self.blend.render(sources, out, wait=wait)
        (a, wa), (b, wb) = sources
        if wa < 0 or wb < 0 or wa + wb != 256:
            raise InvalidArgumentError(f"blend weights must be non-negative and sum to 256, not {wa} and {wb}")
        index, sign = hit
        if sign < 0:  # the stored flow runs from b to a: swap the roles (the formula is symmetric)
            a, wa, b, wb = b, wb, a, wa
        self.warped += 1
        if self._cl is not None:
            return self._cl.render(a, b, wa, wb, index, out, wait)
        warp_reference(self.blend._frames, a, b, wa, wb, self._flows[index], self.step_log2, out)
        return None

    def draw(self, out: np.ndarray, sources: tuple[tuple[int, int], ...], *, wait: bool = True):
        """:meth:`render`, in the words of every engine (:class:`~dynatex.player.engines.Engine`)."""
        return self.render(sources, out, wait=wait)

    def close(self) -> None:
        """Release the flows and the blend engine's device memory."""
        if self._cl is not None:
            self._cl.close()
        self.blend.close()


class _WarpOpenCL:
    """Kernel ``warp2`` of ``kernels/warp.cl`` over an OpenCL blend engine's (RGB) frames."""

    def __init__(self, blend: BlendOpenCL, flows: np.ndarray, step_log2: int, grid, ctx, queue) -> None:
        import pyopencl as cl

        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel

        h, w = blend.shape[:2]
        mf = cl.mem_flags
        host = flows if flows.size else np.zeros(2, np.int16)
        self._d_flows = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=host)
        defines = {"W": w, "H": h, "FRAME_STRIDE": blend._vecs * 16, "GH": grid[0], "GW": grid[1]}
        defines.update(blend.format.defines)  # the blend engine's stack is RGB: the kernel places the pixels
        prog = build_program(ctx, ("pixels.cl", "warp.cl"), {**defines, "STEP_LOG2": step_log2})
        self._kernel = Kernel(prog, "warp2")
        self._kernel.set(frames=blend._d_frames, flows=self._d_flows)
        self._out = FrameOut(ctx, queue, self._kernel, "out", blend.frame_bytes)
        self._gsize = (w, h)

    def render(self, a: int, b: int, wa: int, wb: int, index: int, out: np.ndarray, wait: bool):
        i32 = np.int32
        self._kernel.set(ia=i32(a), ib=i32(b), wa=i32(wa), wb=i32(wb), pair=i32(index))
        return self._out.launch(out, self._gsize, wait=wait)

    def close(self) -> None:
        buf = self.__dict__.pop("_d_flows", None)
        if buf is not None:
            buf.release()


def warp_reference(
    frames: np.ndarray, a: int, b: int, wa: int, wb: int, flow: np.ndarray, step_log2: int, out: np.ndarray
) -> np.ndarray:
    """The numpy reference of the ``warp2`` kernel: frames ``a`` and ``b`` of ``frames``
    ``(T, H, W, C)`` uint8 blended with weights ``wa + wb = 256`` along the grid ``flow``
    ``(Gh, Gw, 2)`` int16 (x, y in 1/16 px, samples every ``2**step_log2`` pixels), into ``out``."""
    h, w = frames.shape[1:3]
    s = 1 << step_log2
    y, x = np.mgrid[0:h, 0:w].astype(np.int32)
    gy, gx, ry, rx = y >> step_log2, x >> step_log2, y & (s - 1), x & (s - 1)
    g = flow.astype(np.int32)
    acc = np.full((h, w, 2), (s * s) >> 1, np.int32)
    for dy, dx, wgt in ((0, 0, (s - rx) * (s - ry)), (0, 1, rx * (s - ry)), (1, 0, (s - rx) * ry), (1, 1, rx * ry)):
        acc += g[gy + dy, gx + dx] * wgt[..., None]
    f = acc >> (2 * step_log2)
    da = (wb * f + 128) >> 8
    db = (wa * f + 128) >> 8
    one = 1 << FLOW_FRACTION_BITS
    va = _sample(frames[a], x * one - da[..., 0], y * one - da[..., 1])
    vb = _sample(frames[b], x * one + db[..., 0], y * one + db[..., 1])
    out[...] = (wa * va + wb * vb + 32768) >> 16
    return out


def _sample(frame: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``frame`` (H, W, C) at ``(px, py)`` in 1/16 px, edge pixels repeated, 8.8 fixed point."""
    h, w = frame.shape[:2]
    x0, y0 = px >> 4, py >> 4
    fx, fy = (px - x0 * 16)[..., None], (py - y0 * 16)[..., None]
    xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    f = frame.astype(np.int32)
    top = f[ya, xa] * (16 - fx) + f[ya, xb] * fx
    bottom = f[yb, xa] * (16 - fx) + f[yb, xb] * fx
    return top * (16 - fy) + bottom * fy
