"""Stochastic tiling of a quilted torus: tiles of any size without a period.

A quilted tile set is one seamless torus (at most 768 px a side); an output larger than it,
laid out as the torus edge to edge, repeats with the torus's period. Here the output is
covered by a triangle grid instead (Heitz and Neyret, High-Performance By-Example Noise
using a Histogram-Preserving Blending Operator, 2018): every vertex shows its own window of
the torus (a random offset, and its own time offset, so windows play out of step), and a
pixel blends the windows of its triangle's three vertices. The blend is Heitz and Neyret's
variance-preserving one in a Gaussianized space: each channel value goes through a table
``T`` (built at open from the torus's histogram) that makes it standard normal, the windows
are summed with weights ``w_i / sqrt(sum w_j^2)`` (the sum keeps the variance, so contrast
does not wash out where windows meet), and the inverse of ``T`` gives the channel back with
the torus's histogram. A vertex takes part where its barycentric coordinate is within
``band`` of the pixel's largest (a smoothstep ramp, :func:`~.stochastic_reference.weight_table`),
so each vertex shows its window alone over most of its hexagon (a plain copy, as the gather
draws) and windows meet in bands about ``band`` times the cell's width wide along the hexagons'
edges (18% of the pixels at the default 0.1). Windows span at most the torus, so a window never
shows the torus's period.

What is fixed at open: the torus and its Gaussianized copy (each channel through ``T``, stored
as bytes as the paper stores it: 32 levels a standard deviation; both RGB whatever the output's
pixel format), the pattern of weights of one grid cell, cut into pieces of at most ``RUN`` pixels
of a row that one window shows alone or that blend the same windows (:func:`cell_pieces`), the
window offsets (from the seed). Per frame the host computes each vertex's stored frame and blend
weight (a few hundred vertices at 4K) and uploads them without waiting; one kernel
(``kernels/stochastic.cl``) draws every piece of every cell once, as whole vectors of RGB bytes: a
copy piece from the torus, a blend piece in integers from the Gaussianized copy with one inverse
lookup per byte; a four-byte format gets them placed as it stores its pixels
(``kernels/pixels.cl``). The numpy reference :func:`~.stochastic_reference.stochastic_reference`
computes the same integers, so the two backends agree exactly (tested on every verified
device); the 8-bit Gaussianized copy gives a value back within one level (98-99%; within 4 in a
sparse tail), in the blend bands only.

Examples
--------
>>> import numpy as np
>>> torus = np.random.default_rng(0).integers(0, 256, (4, 40, 48, 3), dtype=np.uint8)
>>> from dynatex.player.engines import open_engine
>>> s = open_engine("stochastic", torus, (100, 150), seed=1)      # no ctx: the numpy reference
>>> s.set_time_map(np.zeros(s.tmap_shape, np.float32))
>>> out = np.empty(s.out_shape, np.uint8)
>>> s.draw(out, 0.0)                                               # the frame is in out
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import check_float, check_out
from ...errors import InvalidArgumentError
from ..pixels import pixel_format
from .stochastic_reference import (
    BAND,
    N_INVERSE,
    blend_weights,
    gauss_tables,
    gaussianize,
    stochastic_reference,
    tone_gains,
    triangle_cell,
    vertex_grid,
    vertex_pixels,
    vertex_table,
    weight_table,
)

RUN = 32  # output pixels per piece at most
GROUP = 8  # pieces per work-group
ROWS = 256  # output rows per block of the numpy reference (bounded memory)


class Stochastic:
    """Frames of the stochastic layout of one ``torus`` ``(L, TH, TW, 3)`` uint8 at ``out_size``.

    The interface of both engines (:func:`~dynatex.player.engines.open_engine` picks one), shaped
    like the gather engine's where a tiles player uses it: :attr:`tmap_shape` is the vertex grid
    and the time maps hold one offset per vertex (frames; :meth:`set_time_map` with a target fades
    between two, ``draw``'s ``fade``; :meth:`next_time_map` moves on one map; nothing to smooth:
    the blend spreads a window's offset), :meth:`set_tones` takes the tone table of the gather
    (its first row's gains), :meth:`draw` draws a frame at time ``t``.
    ``seed`` draws the window offsets; ``cell`` (default :func:`triangle_cell`, at most the torus's
    width) is the triangle grid's ``(row height, width)``; ``band`` the width of the blend bands
    (:func:`weight_table`).
    """

    backend = ""

    def __init__(
        self,
        torus: np.ndarray,
        out_size: Sequence[int],
        *,
        seed: int = 0,
        cell: Sequence[int] | None = None,
        band: float = BAND,
        format: str = "RGB",
    ) -> None:
        torus = np.asarray(torus)
        if torus.dtype != np.uint8 or torus.ndim != 4 or torus.shape[3] != 3 or torus.shape[0] < 1:
            raise InvalidArgumentError(f"torus must be uint8 (L, h, w, 3) with L >= 1, not {torus.dtype} {torus.shape}")
        self.torus = np.ascontiguousarray(torus)
        self.n_frames, th, tw = (int(v) for v in torus.shape[:3])
        h, w = (int(v) for v in out_size)
        self.format = pixel_format(format)
        self.out_shape = (h, w, self.format.bytes)
        self.cell = triangle_cell((th, tw)) if cell is None else (int(cell[0]), int(cell[1]))
        if self.cell[1] > tw:
            raise InvalidArgumentError(f"cell must be at most as wide as the torus ({tw}), not {self.cell}")
        self.weights = weight_table(self.cell, check_float("band", band, 0.01, 1.0))
        self.tmap_shape = vertex_grid((h, w), self.cell)
        self.vertex_pixels = vertex_pixels((h, w), self.cell)
        self.direct = False
        sample = self.torus[:: max(1, self.n_frames // 16)].reshape(-1, 3)
        self._hist = np.stack([np.bincount(sample[:, ch], minlength=256) for ch in range(3)]).astype(np.float64)
        self.set_windows(seed)
        self._tmap = np.zeros(self.tmap_shape, np.float32)
        self._target: np.ndarray | None = None
        self._gain = np.ones(3)
        self._tables = gauss_tables(self._hist)
        self.gauss_torus = gaussianize(self.torus, self._tables[0])
        self._last_t, self._last_fade = 0.0, 0.0

    # -- what an engine implements --------------------------------------------------------------
    def _upload_tables(self) -> None:
        """Put the Gaussianizing, inverse and tone tables where the frames are drawn."""

    def _launch(self, vertices: np.ndarray, out: np.ndarray):
        """Start the frame of ``vertices`` into ``out``; None or an event."""
        raise NotImplementedError

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for the reference)."""

    # -- inputs --------------------------------------------------------------------------------
    def set_windows(self, seed: int) -> None:
        """Draw every vertex's window offset (into the torus) from ``seed``."""
        rng = np.random.default_rng([int(seed), 0x57C4])
        th, tw = self.torus.shape[1:3]
        self._offsets = np.stack(
            [rng.integers(0, th, self.tmap_shape), rng.integers(0, tw, self.tmap_shape)], -1
        ).astype(np.int64)

    def set_time_map(self, tmap: np.ndarray, target: np.ndarray | None = None) -> None:
        """Per-vertex time offsets (frames, :attr:`tmap_shape`), and optionally the map they fade toward."""
        maps = []
        for name, m in (("tmap", tmap), ("target", target)):
            if m is None:
                maps.append(None)
                continue
            m = np.asarray(m, np.float32)
            if m.shape != self.tmap_shape or not np.isfinite(m).all():
                raise InvalidArgumentError(f"{name} must be finite with shape {self.tmap_shape}, not {m.shape}")
            maps.append(m.copy())
        self._tmap, self._target = maps

    @property
    def time_map(self) -> np.ndarray:
        """The per-vertex time offsets (a copy)."""
        return self._tmap.copy()

    @property
    def target_map(self) -> np.ndarray | None:
        """The per-vertex offsets the time map fades toward, or None (a copy)."""
        return None if self._target is None else self._target.copy()

    def smooth_time_map(self, sigma: float) -> None:
        """Nothing to smooth: a window keeps one offset and the blend spreads it (``sigma`` checked)."""
        check_float("sigma", sigma, 0.0, 1e4)

    def next_time_map(self, target: np.ndarray, sigma: float = 0.0) -> None:
        """Move on one map: the target becomes the time map and ``target`` the new target
        (``sigma`` as :meth:`smooth_time_map`). Needs a target set."""
        if self._target is None:
            raise InvalidArgumentError("next_time_map needs a target: set one with set_time_map(tmap, target)")
        self.smooth_time_map(sigma)
        self.set_time_map(self._target, target)

    def set_tones(self, tones: np.ndarray, offsets: np.ndarray | None = None) -> None:
        """Tone gains: the first row of a gather tone table ``(n, 3)`` (offsets must be 0)."""
        tones = np.asarray(tones, np.float64)
        if offsets is not None and np.any(np.asarray(offsets) != 0):
            raise InvalidArgumentError("the stochastic layout tones by gain only; offsets must be 0")
        self._gain = tones.reshape(-1, 3)[0]
        self._tables = gauss_tables(self._hist, self._gain)
        self._upload_tables()

    def vertices(self, t: float, fade: float = 0.0) -> np.ndarray:
        """The vertex table of the frame at ``t`` (:func:`vertex_table`)."""
        return vertex_table(self._offsets, t, self._tmap, self._target, fade, self.n_frames)

    # -- frames --------------------------------------------------------------------------------
    def render(self, t: float, out: np.ndarray | None = None, *, fade: float = 0.0) -> np.ndarray:
        """The frame at time ``t`` (frames of the torus's loop), into ``out`` when given."""
        if out is None:
            out = np.empty(self.out_shape, np.uint8)
        event = self.start(t, out, fade=fade)
        if event is not None:
            event.wait()
        return out

    def start(self, t: float, out: np.ndarray, *, fade: float = 0.0):
        """Start the frame at ``t`` into ``out``; returns None once it is there, or the event after which it is."""
        check_out(out, self.out_shape)
        if not math.isfinite(float(t)):
            raise InvalidArgumentError(f"t must be finite, not {t!r}")
        self._last_t, self._last_fade = float(t), check_float("fade", fade, 0.0, 1.0)
        return self._launch(self.vertices(self._last_t, self._last_fade), out)

    def draw(self, out: np.ndarray, t: float, *, fade: float = 0.0, wait: bool = True):
        """:meth:`start`, in the words of every engine (:class:`~dynatex.player.engines.Engine`):
        None once ``out`` holds the frame at ``t``, or with ``wait=False`` the event after which it does."""
        event = self.start(t, out, fade=fade)
        if wait and event is not None:
            event.wait()
            return None
        return event

    def render_reference(self, t: float, out: np.ndarray | None = None, *, fade: float = 0.0) -> np.ndarray:
        """The numpy reference of :meth:`render` (either backend)."""
        if out is None:
            out = np.empty(self.out_shape, np.uint8)
        vertices = self.vertices(float(t), fade)
        h, w = self.out_shape[:2]
        for r0 in range(0, h, ROWS):
            rows = range(r0, min(r0 + ROWS, h))
            rgb = stochastic_reference(
                self.torus, self.gauss_torus, self.weights, vertices, *self._tables[1:], (h, w), rows=rows
            )
            self.format.from_rgb(rgb, out[r0 : rows.stop])
        return out

    def frame_traffic(self) -> dict[str, int]:
        """Bytes a frame moves at least: ``output`` written, ``stored`` the torus's two frames
        per window read (an upper bound: windows overlap in the torus)."""
        h, w = self.out_shape[:2]
        th, tw = self.torus.shape[1:3]
        windows = int(np.prod(self.tmap_shape))
        return {"output": h * w * self.format.bytes, "stored": 2 * 3 * min(h * w, windows * th * tw)}

    @property
    def bytes_per_frame(self) -> int:
        """Bytes one render must move at least (:meth:`frame_traffic`)."""
        return sum(self.frame_traffic().values())


class StochasticReference(Stochastic):
    """The numpy engine: every frame is :meth:`Stochastic.render_reference`."""

    backend = "numpy"

    def _launch(self, vertices: np.ndarray, out: np.ndarray):
        self.render_reference(self._last_t, out, fade=self._last_fade)


class StochasticOpenCL(Stochastic):
    """Kernel ``stochastic`` (``kernels/stochastic.cl``) on a device; ``ctx``/``queue`` the player's."""

    backend = "opencl"

    def __init__(
        self,
        torus: np.ndarray,
        out_size: Sequence[int],
        *,
        ctx: Any = None,
        queue: Any = None,
        device: str | None = None,
        **options: Any,
    ) -> None:
        super().__init__(torus, out_size, **options)
        import pyopencl as cl

        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel, context_and_queue

        self.ctx, self.queue = context_and_queue(ctx, queue, device)
        mf = cl.mem_flags
        h, w = self.out_shape[:2]
        th, tw = self.torus.shape[1:3]
        ch, cw = self.cell
        pieces, bweights = cell_pieces(self.weights, RUN)
        self._cells = ((h - 1) // ch + 1, (w - 1 + cw) // cw + 1)
        defines = {
            "TORUS_H": th,
            "TORUS_W": tw,
            "TORUS_WP": tw + RUN,
            "NFRAMES": self.n_frames,
            "CELL_H": ch,
            "CELL_W": cw,
            "VCOLS": self.tmap_shape[1],
            "CELLS_X": self._cells[1],
            "NPIECES": len(pieces),
            "RUN": RUN,
            "N_INVERSE": N_INVERSE,
            **self.format.defines,
        }
        prog = build_program(self.ctx, ("pixels.cl", "stochastic.cl"), defines)
        # RGB, every torus row carrying its first RUN pixels again (no piece wraps)
        pad = np.arange(tw + RUN) % tw
        for name, frames in (("_d_torus", self.torus), ("_d_gauss", self.gauss_torus)):
            padded = np.ascontiguousarray(np.take(frames, pad, axis=2))
            setattr(self, name, cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=padded))
        self._byte_channel = np.tile(np.arange(3), RUN)  # the channel of each RGB byte of a piece

        def table(rows: np.ndarray, dtype) -> Any:
            rows = rows if len(rows) else np.zeros((1,) + rows.shape[1:], rows.dtype)  # no empty buffer
            return cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(rows, dtype))

        self._d_pieces = table(pieces, np.int32)
        self._d_wbytes = table(np.repeat(bweights, 3, axis=-1), np.uint16)  # (blend pieces, 3, 3 RUN)
        self._d_chan = table(self._byte_channel * N_INVERSE, np.int32)
        self._d_gains = cl.Buffer(self.ctx, mf.READ_ONLY, 3 * RUN * 4)
        self._d_inverse = cl.Buffer(self.ctx, mf.READ_ONLY, 3 * N_INVERSE)
        self._vtab = np.zeros(self.tmap_shape + (4,), np.int32)
        self._d_vertices = cl.Buffer(self.ctx, mf.READ_ONLY, self._vtab.nbytes)
        self._k = Kernel(prog, "stochastic")
        self._k.set(
            torus=self._d_torus,
            gauss=self._d_gauss,
            pieces=self._d_pieces,
            wbytes=self._d_wbytes,
            chan=self._d_chan,
            gains=self._d_gains,
            vertices=self._d_vertices,
            inverse=self._d_inverse,
            width=np.int32(w),
            height=np.int32(h),
        )
        self._out = FrameOut(self.ctx, self.queue, self._k, "out", h * w * self.format.bytes)
        self.direct = self._out.direct
        self._local = (GROUP, 1)
        self._size = (_round_up(max(1, len(pieces)), GROUP), self._cells[0] * self._cells[1])
        self._upload_tables()

    def _upload_tables(self) -> None:
        if not hasattr(self, "_k"):
            return  # the base class sets its first tables before the kernel exists
        import pyopencl as cl

        _, inverse, _ = self._tables
        gains = tone_gains(self._gain)[self._byte_channel].astype(np.uint32)
        for buf, host in ((self._d_inverse, inverse), (self._d_gains, gains)):
            cl.enqueue_copy(self.queue, buf, np.ascontiguousarray(host), is_blocking=True)
        self._k.set(toned=np.int32((gains != 256).any()))

    def _upload_vertices(self, vertices: np.ndarray) -> None:
        import pyopencl as cl

        # not waited for: the queue is in order, and the transfer keeps the array until it is done
        self._vtab = np.ascontiguousarray(vertices, np.int32)
        cl.enqueue_copy(self.queue, self._d_vertices, self._vtab, is_blocking=False)

    def _launch(self, vertices: np.ndarray, out: np.ndarray):
        self._upload_vertices(vertices)
        return self._out.launch(out, self._size, self._local, wait=False)

    def render_on_device(self, t: float, *, fade: float = 0.0) -> None:
        """The kernel alone into the device's own frame buffer, waited for (the benchmarks' kernel time)."""
        self._upload_vertices(self.vertices(float(t), fade))
        self._out.launch_on_device(self._size, self._local).wait()

    def close(self) -> None:
        self.queue.finish()
        held = ("_d_torus", "_d_gauss", "_d_pieces", "_d_wbytes", "_d_chan", "_d_gains")
        for name in (*held, "_d_inverse", "_d_vertices"):
            buf = self.__dict__.pop(name, None)
            if buf is not None:
                buf.release()


#: the vertex codes (``kernels/stochastic.cl``) of each triangle's three vertices
TRIANGLE_CODES = np.array([(0, 2, 3), (0, 1, 3), (1, 3, 4)])


def cell_pieces(weights: np.ndarray, run: int) -> tuple[np.ndarray, np.ndarray]:
    """One cell of ``weights`` (:func:`~.stochastic_reference.weight_table`) cut into the kernel's
    pieces, each at most ``run`` pixels of a row, in row order: ``pieces`` ``(n, 8)`` int32 ``(r,
    c, length, blend, code0, code1, code2, row)``; ``blend`` 0: pixels that one window (vertex
    ``code0``) shows alone; 1: pixels that blend at most windows ``code0..2`` (a code repeated
    where fewer take part), weighted by ``bweights[row]``: ``(m, 3, run)`` int, each window's
    weight (``WQ``-ths) at each pixel of the piece (0 past its length and where it takes no part).

    A copy piece is a stretch of one window alone (cut every ``run`` pixels); a blend piece grows
    from its first pixel over the blend pixels after it while at most three windows take part.
    Pixels are grouped into stretches of one key (the window shown alone, or the set of windows
    blending) with numpy; the cut walks the stretches, a few per row."""
    wq = blend_weights(weights)
    ch, cw = wq.shape[:2]
    single = wq[..., 3] >> 2
    codes = TRIANGLE_CODES[wq[..., 3] & 3]  # (ch, cw, 3), a triangle's codes distinct
    copy_code = np.take_along_axis(codes, np.maximum(single - 1, 0)[..., None], -1)[..., 0]
    # key: the code shown alone (0..4), or 8 + the bit set of the codes taking part in a blend
    key = np.where(single > 0, copy_code, 8 + ((wq[..., :3] > 0) << codes).sum(-1))
    start = np.ones((ch, cw), bool)
    start[:, 1:] = key[:, 1:] != key[:, :-1]
    rows, cols = np.nonzero(start)
    ends = np.append(cols[1:], cw)
    ends[np.append(rows[1:] != rows[:-1], True)] = cw
    stretches = list(zip(rows.tolist(), cols.tolist(), ends.tolist(), key[rows, cols].tolist()))
    pieces: list[tuple[int, ...]] = []
    k, pos = 0, -1  # the stretch and the pixel the next piece starts at (-1: the stretch's first)
    while k < len(stretches):
        r, c, e, kk = stretches[k]
        pos = c if pos < 0 else pos
        if kk < 8:
            n = min(run, e - pos)
            pieces.append((r, pos, n, 0, kk, 0, 0, 0))
            pos += n
            k, pos = (k + 1, -1) if pos == e else (k, pos)
            continue
        first, mask = pos, kk - 8
        while True:
            pos = min(e, first + run)
            if pos < e:
                break
            k, pos = k + 1, -1
            if e - first == run or k == len(stretches):
                break
            r2, c2, e2, k2 = stretches[k]
            if r2 != r or k2 < 8 or bin(mask | (k2 - 8)).count("1") > 3:
                break
            mask, e = mask | (k2 - 8), e2
        n = (e if pos < 0 else pos) - first
        taking = [b for b in range(5) if mask >> b & 1]
        pieces.append((r, first, n, 1, *(taking + taking[-1:] * (3 - len(taking))), len(taking)))
    table = np.array(pieces, np.int64).reshape(-1, 8)
    blend = table[:, 3] == 1
    b = table[blend]
    # each code's weight at each pixel, gathered for each blend piece's windows (0 past the
    # piece's length and in the slots that repeat a code)
    code_w = np.zeros((ch, cw, 5), np.int64)
    np.put_along_axis(code_w, codes, wq[..., :3], -1)
    at = np.arange(run)
    cols = np.minimum(b[:, 1:2] + at, cw - 1)
    bweights = code_w[b[:, 0, None, None], cols[:, None, :], b[:, 4:7, None]]
    bweights *= (at < b[:, 2:3])[:, None, :] & (np.arange(3) < b[:, 7:8])[:, :, None]
    table[blend, 7] = np.arange(len(b))
    return table.astype(np.int32), bweights.astype(np.int64).reshape(-1, 3, run)


def _round_up(v: int, m: int) -> int:
    return -(-v // m) * m
