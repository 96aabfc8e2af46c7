"""The runs engine of mode ``evolve``: frames gathered from stored source frames through a
quilt, each pixel at its block's source time, cross-fade bands blending two sources.

The mode owns the time model (clock, rate map, end mode, jitter warps) and hands the engine
a *source time* function; the engine owns the frame stack, the run tables and the kernel
(``kernels/runs.cl``). :class:`RunsReference` evaluates every pixel in numpy (the
reference); :class:`RunsOpenCL` cuts the quilt's rows once into *runs* (:func:`build_runs`)
that read one or two contiguous source rows, so that the kernel moves whole runs with
16-byte vectors, and evaluates the source time once per (rate, block) *time slot* per frame
on the host. Both compute the same float32 formulas; :func:`open_runs` picks one.

A source time function ``source_time(rate, blocks, t)`` returns float32 source times (in
source frames) for clock ``t`` of pixels or slots of the given blocks, at the given rates
(an array of the same shape, or None for rate 1). Rates must be multiples of
:data:`RATE_STEP` (:func:`quantize_rate`): the OpenCL engine cuts its runs where the rate changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ...errors import InvalidArgumentError
from ..pixels import pixel_format

SPILL = 16  # bytes a kernel chunk may read past a run
RATE_STEP = 1.0 / 512  # rate maps are quantized to this step (see quantize_rate)

#: ``(rate or None, blocks, t) -> float32`` source times (module docstring)
SourceTime = Callable[[Any, np.ndarray, np.float32], np.ndarray]


def quantize_rate(rate: np.ndarray) -> np.ndarray:
    """The rate map the frames use: rounded to the nearest multiple of ``RATE_STEP`` (1/512), float32.

    Both backends play the quantized map, so that the OpenCL player can cut its runs where
    the rate changes and give every piece one host-computed time per frame instead of a
    per-pixel time. The rate moves by at most 1/1024, so a pixel's local time ``t * M`` by
    at most ``t / 1024`` frames (0.1 frame at t = 100); where a smoothed map changes by
    less than a step from one pixel to the next, it becomes steps of ``t / 512`` frames.
    The step is a compromise between a visible seam (coarser steps cut a smoothed band
    into visible levels) and the size of the slot tables (finer steps), measured in
    CHANGELOG.md. An unsmoothed map that changes at every pixel plays, but at a run (and a
    slot) per pixel.

    Examples
    --------
    >>> quantize_rate(np.array([1.0, 1.0009, 1.004, 2.0])).tolist()
    [1.0, 1.0, 1.00390625, 2.0]
    """
    return np.ascontiguousarray(np.rint(np.asarray(rate, np.float64) / RATE_STEP) * RATE_STEP, np.float32)


def _segments(key_a: np.ndarray, key_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts (row-major pixel index) and lengths of the maximal row segments of constant keys."""
    h, w = key_a.shape
    brk = np.ones((h, w), bool)
    brk[:, 1:] = (key_a[:, 1:] != key_a[:, :-1]) | (key_b[:, 1:] != key_b[:, :-1])
    starts = np.flatnonzero(brk.ravel())
    return starts, np.diff(np.append(starts, h * w))


def _merge_plain(key_a, key_b, swap, key_p, span: int, n_pixels: int | None):
    """Fold each plain run into a neighbouring band of its row (the previous one, else the
    next) whose stream pair holds its stream, unless the band's other stream, which the
    kernel then reads (at weight 0) over the run's pixels, would leave the source frame
    (``n_pixels``; a stream need not extend beyond its band in a hostile database)."""
    h, w = key_a.shape
    starts, lengths = _segments(key_a, key_b)
    ka, kb = key_a.ravel()[starts], key_b.ravel()[starts]
    row = starts // w
    plain = kb < 0
    n = len(starts)
    prev = np.arange(n) - 1
    nxt = np.arange(n) + 1
    ok_prev = plain & (prev >= 0)
    ok_prev[ok_prev] &= (
        (row[prev[ok_prev]] == row[ok_prev])
        & (kb[prev[ok_prev]] >= 0)
        & ((ka[prev[ok_prev]] == ka[ok_prev]) | (kb[prev[ok_prev]] == ka[ok_prev]))
    )
    ok_next = plain & ~ok_prev & (nxt < n)
    ok_next[ok_next] &= (
        (row[nxt[ok_next]] == row[ok_next])
        & (kb[nxt[ok_next]] >= 0)
        & ((ka[nxt[ok_next]] == ka[ok_next]) | (kb[nxt[ok_next]] == ka[ok_next]))
    )
    target = np.where(ok_prev, prev, np.where(ok_next, nxt, -1))
    run_of = np.repeat(np.arange(n), lengths)
    tgt = target[run_of].reshape(h, w)
    moved = tgt >= 0
    if n_pixels is not None and moved.any():
        ta, tb = ka[tgt[moved]], kb[tgt[moved]]
        other = np.where(ta == key_p[moved], tb, ta)
        x = np.broadcast_to(np.arange(w, dtype=np.int64)[None, :], (h, w))[moved]
        src = other % span - w + x
        outside = run_of.reshape(h, w)[moved][(src < 0) | (src >= n_pixels)]
        if outside.size:
            target[np.unique(outside)] = -1
            tgt = target[run_of].reshape(h, w)
            moved = tgt >= 0
    key_a, key_b, swap = key_a.copy(), key_b.copy(), swap.copy()
    key_a[moved] = ka[tgt[moved]]
    key_b[moved] = kb[tgt[moved]]
    swap[moved] = key_p[moved] == key_b[moved]
    return key_a, key_b, swap


def build_runs(
    pix: np.ndarray,
    labels: np.ndarray,
    wq: np.ndarray | None = None,
    pix2: np.ndarray | None = None,
    labels2: np.ndarray | None = None,
    *,
    merge: bool = True,
    n_pixels: int | None = None,
    pixel_bytes: int = 3,
) -> dict[str, np.ndarray]:
    """Cut the quilt's rows into runs, the unit of work of kernel ``evolve``.

    A *stream* is one block's source at a constant offset along a row (source pixel =
    output column + offset). A run is a maximal segment of one row that reads one stream
    (plain: no cross-fade) or one unordered pair of streams (a cross-fade band, which keeps
    its pair on both sides of the cut, where the primary and second sources swap). With
    ``merge`` (default), a plain run next to a band of its row whose pair holds its stream
    joins that band, its pixels blending with weight 0 (exactly the plain value): fewer,
    longer runs, which the kernel does faster than more, shorter ones. ``n_pixels`` (the
    source frame's pixels) keeps every stream a run reads inside the frame: a merge that would
    read the band's other stream outside it is not made.

    Returns ``starts`` (first output pixel, row-major index, int64), ``lengths``, and the
    kernel tables: ``runs`` ``(n, 4)`` int32 (first pixel, stream A's source pixel there,
    block of A, length | blend << 31 | spill << 30: the run's last 16-byte chunk may run
    past its end and stays within the row), ``runs_b`` ``(n, 2)`` int32 (stream B's source pixel
    and block), ``row_start`` ``(H + 1,)`` int32, and ``code`` ``(H * W * pixel_bytes,)`` uint16 per
    stack byte: weight of the second source in 1/256 (bits 0-8), bit 9 set when the
    primary source is stream B (0 outside bands).

    Examples
    --------
    >>> pix = np.array([[5, 6, 7, 0, 1]]); lab = np.array([[0, 0, 0, 1, 1]])
    >>> r = build_runs(pix, lab)
    >>> r["runs"].tolist(), r["row_start"].tolist()
    ([[0, 5, 0, 3], [3, 0, 1, 2]], [0, 2])
    >>> build_runs(np.arange(48)[None], np.zeros((1, 48)))["runs"][:, 3] == 48 | 1 << 30
    array([ True])
    """
    h, w = pix.shape
    x = np.arange(w, dtype=np.int64)[None, :]
    pix = np.asarray(pix, np.int64)
    labels = np.asarray(labels, np.int64)
    span = int(max(pix.max(initial=0), 0 if pix2 is None else pix2.max(initial=0))) + w + 1
    key_p = labels * span + (pix - x + w)
    if wq is None or not (wq > 0).any():
        blend = np.zeros((h, w), bool)
        key_a, key_b = key_p, np.full((h, w), -1, np.int64)
        swap = blend
    else:
        blend = wq > 0
        key_s = np.asarray(labels2, np.int64) * span + (np.asarray(pix2, np.int64) - x + w)
        key_a = np.where(blend, np.minimum(key_p, key_s), key_p)
        key_b = np.where(blend, np.maximum(key_p, key_s), -1)
        swap = blend & (key_p > key_s)
    if merge and blend.any():
        key_a, key_b, swap = _merge_plain(key_a, key_b, swap, key_p, span, n_pixels)
    starts, lengths = _segments(key_a, key_b)
    col = starts % w
    ka, kb = key_a.ravel()[starts], key_b.ravel()[starts]
    is_blend = kb >= 0
    kb = np.where(is_blend, kb, ka)
    runs = np.empty((len(starts), 4), np.int64)
    runs[:, 0] = starts
    runs[:, 1] = ka % span - w + col
    runs[:, 2] = ka // span
    pb = pixel_bytes
    may_spill = col * pb + -(-lengths * pb // SPILL) * SPILL <= w * pb  # the last chunk stays in the row
    runs[:, 3] = lengths | (is_blend.astype(np.int64) << 31) | (may_spill.astype(np.int64) << 30)
    runs_b = np.stack([kb % span - w + col, kb // span], axis=1)
    code = swap.astype(np.uint16) << 9
    if blend.any():
        code[blend] |= np.asarray(wq)[blend].astype(np.uint16)
    return {
        "starts": starts,
        "lengths": lengths,
        "runs": runs.astype(np.uint32).view(np.int32),
        "runs_b": runs_b.astype(np.int32),
        "row_start": np.searchsorted(starts, np.arange(h + 1) * w).astype(np.int32),
        "code": np.repeat(code.ravel(), pixel_bytes),
    }


def check_runs(runs: dict[str, np.ndarray], n_pixels: int, n_blocks: int) -> None:
    """Every source pixel and block the run tables make kernel ``evolve`` read lies inside the
    stack: the last guard between a database's maps and a read out of bounds."""
    r = runs["runs"].view(np.uint32).astype(np.int64)
    length = r[:, 3] & ((1 << 30) - 1)
    first = runs["runs"][:, 1].astype(np.int64)
    first_b = runs["runs_b"][:, 0].astype(np.int64)
    blend = (r[:, 3] >> 31) == 1
    bad = (first < 0) | (first + length > n_pixels) | (r[:, 2] >= n_blocks)
    bad |= blend & ((first_b < 0) | (first_b + length > n_pixels) | (runs["runs_b"][:, 1] >= n_blocks))
    if bad.any():
        raise InvalidArgumentError(
            f"the quilt's maps make {int(bad.sum())} run(s) read outside the source frames "
            f"({n_pixels} pixels, {n_blocks} blocks): the database is inconsistent"
        )


def cut_runs(
    base: dict[str, np.ndarray], rate: np.ndarray | None, shape: tuple[int, int], n_blocks: int, *, pixel_bytes: int = 3
):
    """The run tables of :func:`build_runs`'s runs ``base`` for a rate map (None: uniform rate 1):
    the runs cut where the quantized rate changes along a row, and their time slots.

    Returns ``runs``, ``runs_b``, ``row_start``, ``pair`` ``(n, 2)`` int32 (the slots of
    streams A and B of each run), ``slot_block`` (block of each slot) and ``slot_rate``
    (rate of each slot, float32, or None for a uniform rate: the slots are the blocks).
    """
    runs, runs_b = base["runs"], base["runs_b"]
    if rate is None:
        pair = np.stack([runs[:, 2], runs_b[:, 1]], axis=1).astype(np.int32)
        return runs, runs_b, base["row_start"], pair, np.arange(n_blocks, dtype=np.int64), None
    h, w = shape
    flat = rate.reshape(-1)
    brk = np.zeros(flat.size, bool)
    brk[base["starts"]] = True
    brk[1:] |= flat[1:] != flat[:-1]
    starts = np.flatnonzero(brk)
    parent = np.searchsorted(base["starts"], starts, side="right") - 1
    off = starts - base["starts"][parent]
    lengths = np.diff(np.append(starts, flat.size))
    col = starts % w
    flags = runs[parent, 3].view(np.uint32).astype(np.int64) & (1 << 31)
    pb = pixel_bytes
    may_spill = col * pb + -(-lengths * pb // SPILL) * SPILL <= w * pb
    r = np.empty((len(starts), 4), np.int64)
    r[:, 0] = starts
    r[:, 1] = runs[parent, 1] + off
    r[:, 2] = runs[parent, 2]
    r[:, 3] = lengths | flags | (may_spill.astype(np.int64) << 30)
    cut = r.astype(np.uint32).view(np.int32)
    cut_b = np.stack([runs_b[parent, 0] + off, runs_b[parent, 1]], axis=1).astype(np.int32)
    row_start = np.searchsorted(starts, np.arange(h + 1) * w).astype(np.int32)
    level = np.rint(flat[starts].astype(np.float64) / RATE_STEP).astype(np.int64)
    keys = np.concatenate([level * n_blocks + cut[:, 2], level * n_blocks + cut_b[:, 1]])
    uniq, inverse = np.unique(keys, return_inverse=True)
    pair = inverse.reshape(2, -1).T.astype(np.int32)
    return cut, cut_b, row_start, pair, uniq % n_blocks, ((uniq // n_blocks) * RATE_STEP).astype(np.float32)


def sample(flat: np.ndarray, pix: np.ndarray, s: np.ndarray, *, loop: bool, interpolate: bool) -> np.ndarray:
    """Pixels ``pix`` of a stack ``(N, P, 3)`` at source times ``s`` (float32; frames folded by
    ``loop``, else held at the ends), linearly between frames when ``interpolate``."""
    n = flat.shape[0]
    si = np.floor(s).astype(np.int64)
    fold = (lambda i: np.mod(i, n)) if loop else (lambda i: np.clip(i, 0, n - 1))
    v = flat[fold(si), pix].astype(np.float32)
    if interpolate:
        f = (s - si.astype(np.float32))[..., None].astype(np.float32)
        v1 = flat[fold(si + 1), pix].astype(np.float32)
        v = v + f * (v1 - v)
    return v


class Runs:
    """What both runs engines share: the quilt's maps, checked, and the interface.

    Parameters
    ----------
    frames : (N, P, 3) uint8
        The stored source frames, pixels flattened (``P = h * w``).
    shape : (H, W)
        Output size (the quilt's canvas).
    pix, labels : (H, W) int
        Source pixel (index into ``P``) and block of every output pixel.
    n_blocks : int
        Blocks of the quilt (every label is below it).
    blend : (weight, pix2, labels2), optional
        Cross-fade bands: the second source's weight in 1/256 (0 outside bands), its pixel and block.
    gain : (H, W, 3) float32, optional
        Per-pixel colour gain applied last.
    interpolate : bool
        Blend linearly between source frames at fractional times.
    format : {"RGB", "RGBA", "BGRA"}
        Output pixel format (:data:`~dynatex.player.pixels.FORMATS`).
    """

    backend = ""

    def __init__(
        self,
        frames: np.ndarray,
        shape: tuple[int, int],
        pix: np.ndarray,
        labels: np.ndarray,
        *,
        n_blocks: int,
        blend: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        gain: np.ndarray | None = None,
        interpolate: bool = True,
        format: str = "RGB",
    ) -> None:
        self.format = pixel_format(format)
        self.flat = frames
        self.n_frames, self.n_pixels = int(frames.shape[0]), int(frames.shape[1])
        self.shape = (int(shape[0]), int(shape[1]))
        self.pix, self.labels = pix, labels
        self.n_blocks = int(n_blocks)
        self.blend = blend
        self.gain = gain
        self.interpolate = bool(interpolate)
        self.rate: np.ndarray | None = None

    def set_rate(self, rate: np.ndarray | None) -> None:
        """The per-pixel rate ``(H, W)`` float32 (multiples of :data:`RATE_STEP`), or None for 1."""
        self.rate = rate

    def start(self, t: float, out: np.ndarray, *, source_time: SourceTime, loop: bool, wait: bool = False):
        """Render the frame at clock ``t`` into ``out``; None once it is there, else the event after which it is.

        ``loop``: source frames past the last wrap to the first (else they hold the last).
        """
        raise NotImplementedError

    def draw(self, out: np.ndarray, t: float, *, source_time: SourceTime, loop: bool, wait: bool = True):
        """:meth:`start`, in the words of every engine (:class:`~dynatex.player.engines.Engine`)."""
        return self.start(t, out, source_time=source_time, loop=loop, wait=wait)

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a frame moves at least (what the engine reads and writes)."""
        raise NotImplementedError

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for the reference)."""


class RunsReference(Runs):
    """The numpy reference: every pixel's source time, sample, blend and gain, in float32."""

    backend = "numpy"

    def start(self, t: float, out: np.ndarray, *, source_time: SourceTime, loop: bool, wait: bool = False):
        t32 = np.float32(t)
        v = sample(
            self.flat, self.pix, source_time(self.rate, self.labels, t32), loop=loop, interpolate=self.interpolate
        )
        if self.blend is not None:
            wq, pix2, labels2 = self.blend
            sel = wq > 0
            s2 = source_time(None if self.rate is None else self.rate[sel], labels2[sel], t32)
            v2 = sample(self.flat, pix2[sel], s2, loop=loop, interpolate=self.interpolate)
            a = (wq[sel].astype(np.float32) * np.float32(1.0 / 256.0))[:, None]
            v[sel] = v[sel] + a * (v2 - v[sel])
        if self.gain is not None:
            v = v * self.gain
        rgb = np.clip(np.rint(v), 0, 255).astype(np.uint8).reshape(*self.shape, 3)
        self.format.from_rgb(rgb, out)

    @property
    def bytes_per_frame(self) -> int:
        """Per-pixel maps as packed tables (source, label, rate), gain, the source pixels read
        (two frames each when interpolating) and the output."""
        h, w = self.shape
        px = h * w
        maps = px * (4 + (2 if self.n_blocks <= 0xFFFF else 4) + (4 if self.rate is not None else 0))
        gain = 12 * px if self.gain is not None else 0
        return int(maps + gain + (2 if self.interpolate else 1) * 3 * px + (3 + self.format.bytes) * px)


class RunsOpenCL(Runs):
    """Kernel ``evolve`` over run tables (module docstring; ``kernels/runs.cl``).

    ``ctx`` and ``queue`` belong to the caller (the mode's player); the engine owns its
    buffers, built and bounds-checked at construction (:func:`check_runs`) and again for
    every rate map.
    """

    backend = "opencl"

    def __init__(
        self,
        frames: np.ndarray,
        shape: tuple[int, int],
        pix: np.ndarray,
        labels: np.ndarray,
        *,
        ctx: Any,
        queue: Any,
        **options: Any,
    ) -> None:
        super().__init__(frames, shape, pix, labels, **options)
        import pyopencl as cl

        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel

        h, w = self.shape
        pb = self.format.bytes
        # the stack, codes and gains stay RGB (3 bytes a pixel) whatever the format: a four-byte
        # output's row is drawn as RGB, then spread to its pixels (kernels/runs.cl)
        if self.blend is not None:
            wq, pix2, labels2 = self.blend
            runs = build_runs(pix, labels, wq, pix2, labels2, n_pixels=self.n_pixels)
        else:
            runs = build_runs(pix, labels, n_pixels=self.n_pixels)
        check_runs(runs, self.n_pixels, self.n_blocks)
        self.ctx, self.queue = ctx, queue
        self._n_blend_bytes = int(3 * runs["lengths"][runs["runs"][:, 3] < 0].sum())
        self._base = runs
        mf = cl.mem_flags
        ro = mf.READ_ONLY | mf.COPY_HOST_PTR
        pad = SPILL  # a spilling chunk may read past the ends (values unused)
        self._d_stack = cl.Buffer(ctx, ro, hostbuf=np.concatenate([frames.reshape(-1), np.zeros(pad, np.uint8)]))
        self._stack_bytes = frames.nbytes
        self._d_code = cl.Buffer(ctx, ro, hostbuf=np.concatenate([runs["code"], np.zeros(pad, np.uint16)]))
        gain = np.zeros(4, np.float32) if self.gain is None else self.gain.astype(np.float32).reshape(-1)
        self._d_gain = cl.Buffer(ctx, ro, hostbuf=np.concatenate([gain, np.zeros(pad, np.float32)]))
        defines = {"INTERP": self.interpolate, "GAIN": self.gain is not None, "WIDTH": w, **self.format.defines}
        self._kernel = Kernel(build_program(ctx, ("pixels.cl", "runs.cl"), defines), "evolve")
        self._kernel.set(stack=self._d_stack, code=self._d_code, gain=self._d_gain, height=np.int32(h))
        #: the kernel's frame destination (writes straight into callers' arrays where the device shares host memory)
        self.out = FrameOut(ctx, queue, self._kernel, "out", h * w * pb)
        self._gsize = (h,)
        self._bframe_upload = None
        self.set_rate(None)

    def set_rate(self, rate: np.ndarray | None) -> None:
        """Cut the open-time runs where the rate changes along a row and make their time slots:
        the distinct (rate, block) pairs the runs' streams read, whose frames the host computes
        each frame. With a uniform rate the slots are the blocks."""
        import pyopencl as cl

        super().set_rate(rate)
        runs, runs_b, row_start, pair, self._slot_block, self._slot_rate = cut_runs(
            self._base, rate, self.shape, self.n_blocks
        )
        self.n_runs = len(runs)
        self._bframe = np.zeros((len(self._slot_block), 4), np.int32)
        ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        self._d_runs = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(runs))
        self._d_runs_b = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(runs_b))
        self._d_row_start = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(row_start))
        self._d_pair = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(pair))
        self._d_bframe = cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY, self._bframe.nbytes)
        self._kernel.set(
            runs=self._d_runs,
            runs_b=self._d_runs_b,
            row_start=self._d_row_start,
            run_pair=self._d_pair,
            bframe=self._d_bframe,
        )
        h, w = self.shape
        #: bytes the engine keeps on the device
        self.device_bytes = int(
            self._stack_bytes
            + self._base["code"].nbytes
            + h * w * self.format.bytes
            + (self.gain.nbytes if self.gain is not None else 0)
            + runs.nbytes
            + runs_b.nbytes
            + row_start.nbytes
            + pair.nbytes
            + self._bframe.nbytes
        )

    def slot_frames(self, t: float, source_time: SourceTime, loop: bool) -> np.ndarray:
        """Per time slot, what the kernel reads for clock ``t``: the byte offsets of the two
        source frames and the fraction (the float32 formulas of :func:`sample`)."""
        s = np.asarray(source_time(self._slot_rate, self._slot_block, np.float32(t)), np.float32)
        si = np.floor(s)
        i0 = si.astype(np.int32)
        n, fb = self.n_frames, self.n_pixels * 3
        i1 = i0 + 1
        if loop:
            i0, i1 = np.mod(i0, n), np.mod(i1, n)
        else:
            i0, i1 = np.clip(i0, 0, n - 1), np.clip(i1, 0, n - 1)
        b = self._bframe
        b[:, 0] = i0 * fb
        b[:, 1] = (i1 if self.interpolate else i0) * fb
        b[:, 2] = (s - si).astype(np.float32).view(np.int32)
        return b

    def _upload(self, t: float, source_time: SourceTime, loop: bool) -> None:
        import pyopencl as cl

        # a copy, since the previous frame's upload may still wait in the queue; the event is
        # kept because dropping it would wait for the copy (and the frame before it)
        self._bframe_upload = cl.enqueue_copy(
            self.queue, self._d_bframe, self.slot_frames(t, source_time, loop).copy(), is_blocking=False
        )

    def start(self, t: float, out: np.ndarray, *, source_time: SourceTime, loop: bool, wait: bool = False):
        self._upload(t, source_time, loop)
        return self.out.launch(out, self._gsize, wait=wait)

    def run_on_device(self, t: float, *, source_time: SourceTime, loop: bool):
        """Enqueue the kernel for clock ``t`` into the device buffer alone and return its event
        (the benchmarks' kernel-only time)."""
        self._upload(t, source_time, loop)
        return self.out.launch_on_device(self._gsize)

    @property
    def direct(self) -> bool:
        """Frames are written straight into the caller's array (no copy)."""
        return self.out.direct

    @property
    def bytes_per_frame(self) -> int:
        """Run tables, time slots, blend codes, gain, source pixels (RGB; two frames per source
        when interpolating), and the output (copied to the caller unless written directly)."""
        h, w = self.shape
        px = h * w
        pb = self.format.bytes
        per_src = 2 if self.interpolate else 1
        gain = 12 * px if self.gain is not None else 0
        src = per_src * (3 * px + self._n_blend_bytes)
        out = pb * px if self.direct else 2 * pb * px
        return int(32 * self.n_runs + 16 * len(self._slot_block) + 2 * self._n_blend_bytes + gain + src + out)

    def close(self) -> None:
        if self._bframe_upload is not None:
            self._bframe_upload.wait()
        for name in ("_d_stack", "_d_code", "_d_gain", "_d_runs", "_d_runs_b", "_d_row_start", "_d_pair", "_d_bframe"):
            buf = self.__dict__.pop(name, None)
            if buf is not None:
                buf.release()


def open_runs(
    frames: np.ndarray,
    shape: tuple[int, int],
    pix: np.ndarray,
    labels: np.ndarray,
    *,
    ctx: Any = None,
    queue: Any = None,
    **options: Any,
) -> Runs:
    """The OpenCL runs engine on ``ctx``/``queue``, or the numpy reference when ``ctx`` is None."""
    if ctx is None:
        return RunsReference(frames, shape, pix, labels, **options)
    return RunsOpenCL(frames, shape, pix, labels, ctx=ctx, queue=queue, **options)
