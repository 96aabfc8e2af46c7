"""Mode ``evolve``: time-varying textures (rust spreading, honey melting) played from a quilt.

The analyzer's quilt says, for every output pixel, which source pixel it copies and which
placed block it belongs to. Frame ``t`` is a gather from the stored source frames through
that map, at a per-pixel source time built in three steps:

1. **rate map** ``M(y, x)``: local time ``tau = t * M`` (the seed's eq. 8), so brighter
   regions of ``M`` evolve faster; ``M`` may be Gaussian-smoothed so that regions of
   different rate meet without a seam, and is then quantized to steps of 1/512
   (:func:`quantize_rate`);
2. **end mode** (a control): after the last source frame ``tau`` holds there, loops to the
   first frame, or plays back and forth (``hold``, ``loop``, ``pingpong``);
3. **time jitter** per block (the seed's eq. 6-7): source time ``f_b(tau)``, a monotone
   random walk ``f(k+1) = f(k) + 1 + d``, ``d`` uniform in [-1, 1], kept within ``e``
   frames of the true time (and brought back to it at both ends of the timeline), so
   copies of one source block no longer change on the same frame.

Pixels in a quilt's cross-fade band blend their second source (with its own block's time).
One OpenCL kernel (``kernels/quilt.cl``) does it all per frame; the numpy reference below
evaluates the same float32 formulas. At open the player cuts the quilt's rows into *runs*
(:func:`build_runs`): segments that copy a contiguous run of one source row, or blend two
(a cross-fade band), so that the kernel moves whole runs with 16-byte vectors instead of
gathering pixel by pixel; with a rate map the runs are cut further where the quantized rate
changes, and the host computes once per frame the source frames of every (rate, block) pair
that a run reads. The shared gather machinery (:mod:`.gather`) supplies
the packing of source entries and the Gaussian smoothing; its kernel adds a per-pixel
*offset* to one global time, which cannot express a per-pixel rate times the time or a
per-block time warp without re-uploading a full time map every frame, hence the own kernel.
"""
from __future__ import annotations

import os
from typing import Any, Sequence

import numpy as np

from ..tiledb import QuiltModel, TileDB
from .base import FloatControl, Player, check_float, check_seed
from .gather import gaussian_smooth
from .ratemap import check_rate_map

ENDS = ("hold", "loop", "pingpong")
SPEED_RANGE = (-16.0, 16.0)
MAX_SIGMA = 1024.0
SPILL = 16           # bytes a kernel chunk may read past a run
RATE_STEP = 1.0 / 512  # rate maps are quantized to this step (see quantize_rate)


# -- time functions (numpy; the kernel mirrors them) -------------------------------------------
def jitter_warp(n_blocks: int, n_frames: int, jitter: float, *, end: str = "hold", seed: int = 0) -> np.ndarray:
    """Per-block monotone time warps ``(n_blocks, n_frames + 1)`` float32, knot ``k`` = source time at local time ``k``.

    The seed's eq. 7 per block: ``f(0) = 0``, ``f(k+1) = f(k) + 1 + d`` with ``d`` uniform in
    [-1, 1], except that ``d`` is cut back whenever ``|f(k+1) - (k+1)|`` would exceed the
    tolerance. The tolerance is ``e`` tapered to 0 at the ends of the timeline (``min(e, k,
    K - k)``, ``K`` the last frame, or ``n_frames`` for ``loop``), so every block starts and
    ends on the true frame: a held texture reaches the source's final appearance everywhere.
    Each step is in [0, 2]: the warp never runs backwards.

    Examples
    --------
    >>> w = jitter_warp(3, 50, 4.0, seed=1)
    >>> bool((np.diff(w, axis=1) >= 0).all()), bool(np.abs(w - np.arange(51)).max() <= 4)
    (True, True)
    """
    if end not in ENDS:
        raise ValueError(f"end must be one of {ENDS}, not {end!r}")
    jitter = check_float("jitter", jitter, 0.0, float(n_frames))
    k = np.arange(n_frames + 1, dtype=np.float64)
    last = float(n_frames if end == "loop" else n_frames - 1)
    bound = np.clip(np.minimum(np.minimum(jitter, k), last - k), 0.0, None)
    rng = np.random.default_rng(seed)
    dev = np.zeros(n_blocks)
    out = np.empty((n_blocks, n_frames + 1), np.float64)
    out[:, 0] = 0.0
    if jitter > 0:
        d = rng.uniform(-1.0, 1.0, (n_frames, n_blocks))
    for i in range(1, n_frames + 1):
        if jitter > 0:
            step = dev + d[i - 1]
            dev = np.where(np.abs(step) <= bound[i], step, dev)     # the seed: d = 0 if it would leave the band
            dev = np.clip(dev, -bound[i], bound[i])                 # the taper pulls back by at most 1 a step
        out[:, i] = k[i] + dev
    return np.clip(out, 0.0, last).astype(np.float32)


def fold_time(tau: np.ndarray, n_frames: int, end: str) -> np.ndarray:
    """Local time folded onto the source timeline by the end mode (float32, as the kernel)."""
    tau = np.asarray(tau, np.float32)
    n = n_frames
    if end == "hold":
        return np.clip(tau, np.float32(0), np.float32(n - 1))
    if end == "loop":
        p = np.float32(n)
        m = tau - p * np.floor(tau * (np.float32(1.0) / np.float32(n)))
        return np.clip(m, np.float32(0), p).astype(np.float32)
    if n == 1:
        return np.zeros_like(tau)
    p = np.float32(2 * (n - 1))
    m = tau - p * np.floor(tau * (np.float32(1.0) / p))
    m = np.clip(m, np.float32(0), p)
    return np.where(m <= np.float32(n - 1), m, p - m).astype(np.float32)


def warp_time(warp: np.ndarray, labels: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Source time of each pixel: its block's warp evaluated at ``tau`` (piecewise linear)."""
    knots = warp.shape[1]
    k = np.clip(np.floor(tau).astype(np.int64), 0, knots - 2)
    fr = (tau - k.astype(np.float32)).astype(np.float32)
    w0 = warp[labels, k]
    return (w0 + fr * (warp[labels, k + 1] - w0)).astype(np.float32)


def quantize_rate(rate: np.ndarray) -> np.ndarray:
    """The rate map the frames use: rounded to the nearest multiple of ``RATE_STEP`` (1/512), float32.

    Both backends play the quantized map, so that the OpenCL player can cut its runs where
    the rate changes and give every piece one host-computed time per frame instead of a
    per-pixel time. The rate moves by at most 1/1024, so a pixel's local time ``t * M`` by
    at most ``t / 1024`` frames (0.1 frame at t = 100); where a smoothed map changes by
    less than a step from one pixel to the next, it becomes steps of ``t / 512`` frames.
    On a 1024x1024 canvas, a 2 / 1 map smoothed with sigma 16 adds ~80k runs and ~8k
    (rate, block) time slots to the uniform rate's 75k runs and 2.2k slots (1/64 cut the
    band's centre in steps of two levels, which showed as a seam there; 1/1024 made the
    slot tables the bottleneck). An unsmoothed map that changes at every pixel plays, but
    at a run (and a slot) per pixel.

    Examples
    --------
    >>> quantize_rate(np.array([1.0, 1.0009, 1.004, 2.0])).tolist()
    [1.0, 1.0, 1.00390625, 2.0]
    """
    return np.ascontiguousarray(np.rint(np.asarray(rate, np.float64) / RATE_STEP) * RATE_STEP, np.float32)


def _frame_index(i: np.ndarray, n: int, end: str) -> np.ndarray:
    return np.mod(i, n) if end == "loop" else np.clip(i, 0, n - 1)


def _sample(flat: np.ndarray, pix: np.ndarray, s: np.ndarray, end: str, interpolate: bool) -> np.ndarray:
    n = flat.shape[0]
    si = np.floor(s).astype(np.int64)
    v = flat[_frame_index(si, n, end), pix].astype(np.float32)
    if interpolate:
        f = (s - si.astype(np.float32))[..., None].astype(np.float32)
        v1 = flat[_frame_index(si + 1, n, end), pix].astype(np.float32)
        v = v + f * (v1 - v)
    return v


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
    ok_prev[ok_prev] &= (row[prev[ok_prev]] == row[ok_prev]) & (kb[prev[ok_prev]] >= 0) & \
        ((ka[prev[ok_prev]] == ka[ok_prev]) | (kb[prev[ok_prev]] == ka[ok_prev]))
    ok_next = plain & ~ok_prev & (nxt < n)
    ok_next[ok_next] &= (row[nxt[ok_next]] == row[ok_next]) & (kb[nxt[ok_next]] >= 0) & \
        ((ka[nxt[ok_next]] == ka[ok_next]) | (kb[nxt[ok_next]] == ka[ok_next]))
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


def build_runs(pix: np.ndarray, labels: np.ndarray, wq: np.ndarray | None = None,
               pix2: np.ndarray | None = None, labels2: np.ndarray | None = None, *,
               merge: bool = True, n_pixels: int | None = None) -> dict[str, np.ndarray]:
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
    and block), ``row_start`` ``(H + 1,)`` int32, and ``code`` ``(H * W * 3,)`` uint16 per
    output byte: weight of the second source in 1/256 (bits 0-8), bit 9 set when the
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
    may_spill = col * 3 + -(-lengths * 3 // SPILL) * SPILL <= w * 3    # the last chunk stays in the row
    runs[:, 3] = lengths | (is_blend.astype(np.int64) << 31) | (may_spill.astype(np.int64) << 30)
    runs_b = np.stack([kb % span - w + col, kb // span], axis=1)
    code = swap.astype(np.uint16) << 9
    if blend.any():
        code[blend] |= np.asarray(wq)[blend].astype(np.uint16)
    return {"starts": starts, "lengths": lengths,
            "runs": runs.astype(np.uint32).view(np.int32), "runs_b": runs_b.astype(np.int32),
            "row_start": np.searchsorted(starts, np.arange(h + 1) * w).astype(np.int32),
            "code": np.repeat(code.ravel(), 3)}


def _check_runs(runs: dict[str, np.ndarray], n_pixels: int, n_blocks: int) -> None:
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
        raise ValueError(f"the quilt's maps make {int(bad.sum())} run(s) read outside the source frames "
                         f"({n_pixels} pixels, {n_blocks} blocks): the database is inconsistent")


class EvolvePlayer(Player):
    """Endless frames of a time-varying texture from its ``quilt`` and stored frames.

    Parameters
    ----------
    db : path or TileDB
        The tile database (the texture needs ``quilt`` data and stored frames).
    texture : str, optional
        Texture name (optional when the database holds one texture).
    backend : {"auto", "opencl", "numpy"}
        See :class:`~dynatex.player.base.Player`.
    device : str, optional
        OpenCL device (see :func:`dynatex.player.opencl.get_context`).
    seed : int
        Seed of the time jitter; the same seed gives the same frames.
    size : (width, height), optional
        Must equal the stored quilt's canvas (the quilt fixes the output size; re-run the
        analysis with another ``size`` for another canvas).
    interpolate : bool
        Blend linearly between source frames at fractional times (otherwise the earlier frame).
    jitter, end, speed, rate_map, rate_sigma
        Initial values of the controls below.

    Controls (attributes, changeable between any two frames)
    ---------------------------------------------------------
    speed : float in [-16, 16]
        Source frames the clock advances per output frame.
    time : float
        The clock (source frames at rate 1); assign to seek.
    jitter : float in [0, n_frames]
        ``e``: largest deviation of a block's time from the true time, in frames.
    end : {"hold", "loop", "pingpong"}
        What happens after the last source frame.
    rate_map : (H, W) array in [0, 64], or None (uniform 1)
        Per-pixel rate ``M``; see :mod:`dynatex.player.ratemap` for generators. Played
        quantized to steps of 1/512 after smoothing (:func:`quantize_rate`).
    rate_sigma : float >= 0
        Gaussian smoothing of the rate map in output pixels (0: none).

    Examples
    --------
    >>> with EvolvePlayer("rust.h5", jitter=4, end="loop") as p:     # doctest: +SKIP
    ...     p.rate_map = ratemap.halves((p.shape[0], p.shape[1]), 2.0, 1.0)
    ...     frame = p.next_frame()
    """

    mode = "evolve"

    def __init__(self, db: str | os.PathLike | TileDB, texture: str | None = None, *,
                 backend: str = "auto", device: str | None = None, seed: int = 0,
                 size: Sequence[int] | None = None, interpolate: bool = True, jitter: float = 0.0,
                 end: str = "hold", speed: float = 1.0, rate_map: np.ndarray | None = None,
                 rate_sigma: float = 0.0) -> None:
        super().__init__(db, texture, backend=backend, device=device)
        try:
            self._setup(self.texture.read("quilt"), seed, size, bool(interpolate))
            self.speed = speed
            self.end = end
            self.jitter = jitter
            self.rate_sigma = rate_sigma
            self.rate_map = rate_map
            self._warm()
        except BaseException:
            self.close()
            raise

    # -- setup ---------------------------------------------------------------------------------
    def _setup(self, model: QuiltModel, seed: int, size, interpolate: bool) -> None:
        w, h = model.size
        if size is not None:
            try:
                sw, sh = (int(v) for v in size)
            except (TypeError, ValueError):
                raise TypeError(f"size must be (width, height), not {size!r}") from None
            if (sw, sh) != (w, h):
                raise ValueError(f"size {sw}x{sh} does not fit the stored quilt, which is {w}x{h}; "
                                 "re-run the analysis with that size (dynatex analyze --quilt-size)")
        self.seed = check_seed("seed", seed)
        self.model_info = dict(model.info)
        self.interpolate = interpolate
        self._shape = (h, w, 3)
        self.n_blocks = model.n_blocks
        src = self.texture.source
        frames = self.texture.frames().read()
        if frames.shape[-1] == 1:
            frames = np.repeat(frames, 3, axis=-1)
        self.n_frames = int(frames.shape[0])
        self._flat = np.ascontiguousarray(frames.reshape(self.n_frames, -1, 3))
        sw = src.width
        self._pix = (model.source_map[..., 0].astype(np.int64) * sw + model.source_map[..., 1]).astype(np.int64)
        self._labels = np.ascontiguousarray(model.labels, np.int64)
        self._blend = model.blend_weight is not None
        if self._blend:
            self._wq = np.rint(model.blend_weight.astype(np.float64) * 256).astype(np.int64)
            self._pix2 = (model.blend_map[..., 0].astype(np.int64) * sw + model.blend_map[..., 1])
            self._labels2 = np.ascontiguousarray(model.blend_labels, np.int64)
        self._gain = None if model.gain is None else np.ascontiguousarray(model.gain, np.float32)
        if self._gain is not None and self._gain.shape[2] == 1:
            self._gain = np.ascontiguousarray(np.repeat(self._gain, 3, axis=2))
        self._clock = 0.0
        self._speed, self._end, self._jitter = 1.0, "hold", 0.0
        self._rate_raw: np.ndarray | None = None
        self._rate: np.ndarray | None = None
        self._rate_sigma = 0.0
        self._warp = jitter_warp(self.n_blocks, self.n_frames, 0.0, seed=self.seed)
        self._index_warp()
        if self.backend == "opencl":
            self._setup_opencl(frames)

    def _setup_opencl(self, frames: np.ndarray) -> None:
        import pyopencl as cl
        from .engine import FrameOut, Kernel
        from .opencl import build_program
        h, w = self._shape[:2]
        mf = cl.mem_flags
        ro = mf.READ_ONLY | mf.COPY_HOST_PTR
        n_pixels = self._flat.shape[1]
        if self._blend:
            runs = build_runs(self._pix, self._labels, self._wq, self._pix2, self._labels2, n_pixels=n_pixels)
        else:
            runs = build_runs(self._pix, self._labels, n_pixels=n_pixels)
        _check_runs(runs, n_pixels, self.n_blocks)
        self._n_blend_bytes = int(3 * runs["lengths"][runs["runs"][:, 3] < 0].sum())
        self._base_runs = runs
        pad = np.zeros(SPILL, np.uint8)   # a spilling chunk may read past the ends (values unused)
        self._d_stack = cl.Buffer(self.ctx, ro, hostbuf=np.concatenate([frames.reshape(-1), pad]))
        self._d_code = cl.Buffer(self.ctx, ro, hostbuf=np.concatenate([runs["code"], np.zeros(SPILL, np.uint16)]))
        gain = np.zeros(4, np.float32) if self._gain is None else self._gain.reshape(-1)
        self._d_gain = cl.Buffer(self.ctx, ro, hostbuf=np.concatenate([gain, np.zeros(SPILL, np.float32)]))
        defines = {"INTERP": self.interpolate, "GAIN": self._gain is not None}
        self._kernel = Kernel(build_program(self.ctx, "quilt.cl", defines), "evolve")
        self._kernel.set(stack=self._d_stack, code=self._d_code, gain=self._d_gain, height=np.int32(h))
        self._out = FrameOut(self.ctx, self.queue, self._kernel, "out", h * w * 3)
        #: frames are written straight into the caller's array (no copy) where the device shares host memory
        self.direct = self._out.direct
        self._gsize = (h,)
        self._set_runs(None)

    def _set_runs(self, rate: np.ndarray | None) -> None:
        """The kernel's run tables for a rate map (None: uniform rate): the open-time runs,
        cut where the (quantized) rate changes along a row, and their time slots: the
        distinct (rate, block) pairs the runs' streams read, whose frames the host computes
        each frame (:meth:`_block_frames`). With a uniform rate the slots are the blocks."""
        import pyopencl as cl
        base = self._base_runs
        runs, runs_b = base["runs"], base["runs_b"]
        if rate is None:
            starts = base["starts"]
            pair = np.stack([runs[:, 2], runs_b[:, 1]], axis=1).astype(np.int32)
            self._pair_block = np.arange(self.n_blocks, dtype=np.int64)
            self._pair_rate = None
            row_start = base["row_start"]
        else:
            h, w = self._shape[:2]
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
            may_spill = col * 3 + -(-lengths * 3 // SPILL) * SPILL <= w * 3
            r = np.empty((len(starts), 4), np.int64)
            r[:, 0] = starts
            r[:, 1] = runs[parent, 1] + off
            r[:, 2] = runs[parent, 2]
            r[:, 3] = lengths | flags | (may_spill.astype(np.int64) << 30)
            runs = r.astype(np.uint32).view(np.int32)
            runs_b = np.stack([runs_b[parent, 0] + off, runs_b[parent, 1]], axis=1).astype(np.int32)
            row_start = np.searchsorted(starts, np.arange(h + 1) * w).astype(np.int32)
            level = np.rint(flat[starts].astype(np.float64) / RATE_STEP).astype(np.int64)
            keys = np.concatenate([level * self.n_blocks + runs[:, 2], level * self.n_blocks + runs_b[:, 1]])
            uniq, inverse = np.unique(keys, return_inverse=True)
            pair = inverse.reshape(2, -1).T.astype(np.int32)
            self._pair_block = uniq % self.n_blocks
            self._pair_rate = ((uniq // self.n_blocks) * RATE_STEP).astype(np.float32)
        self.n_runs = len(starts)
        self._bframe = np.zeros((len(self._pair_block), 4), np.int32)
        ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        self._d_runs = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(runs))
        self._d_runs_b = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(runs_b))
        self._d_row_start = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(row_start))
        self._d_pair = cl.Buffer(self.ctx, ro, hostbuf=np.ascontiguousarray(pair))
        self._d_bframe = cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY, self._bframe.nbytes)
        self._kernel.set(runs=self._d_runs, runs_b=self._d_runs_b, row_start=self._d_row_start,
                         run_pair=self._d_pair, bframe=self._d_bframe)
        self.device_bytes = int(self._flat.nbytes + base["code"].nbytes + self._shape[0] * self._shape[1] * 3
                                + (self._gain.nbytes if self._gain is not None else 0)
                                + runs.nbytes + runs_b.nbytes + row_start.nbytes + pair.nbytes + self._bframe.nbytes)

    def _index_warp(self) -> None:
        self._warp_t = np.ascontiguousarray(self._warp.T)     # (knots, blocks): one row per local time

    def _warm(self) -> None:
        self._draw(0.0, np.empty(self._shape, np.uint8))

    # -- controls ---------------------------------------------------------------------------------
    speed = FloatControl("speed", *SPEED_RANGE)

    @property
    def time(self) -> float:
        """The clock, in source frames at rate 1 (the next frame shows this time)."""
        return self._clock

    @time.setter
    def time(self, value: float) -> None:
        self._clock = check_float("time", value, -1e7, 1e7)

    @property
    def end(self) -> str:
        return self._end

    @end.setter
    def end(self, value: str) -> None:
        if value not in ENDS:
            raise ValueError(f"end must be one of {ENDS}, not {value!r}")
        if value != self._end:
            self._end = value
            self._make_warp()

    @property
    def jitter(self) -> float:
        return self._jitter

    @jitter.setter
    def jitter(self, value: float) -> None:
        v = check_float("jitter", value, 0.0, float(self.n_frames))
        if v != self._jitter:
            self._jitter = v
            self._make_warp()

    def _on_reseed(self) -> None:
        """A new seed draws new jitter warps."""
        self._make_warp()

    def _make_warp(self) -> None:
        self._warp = jitter_warp(self.n_blocks, self.n_frames, self._jitter, end=self._end, seed=self.seed)
        self._index_warp()

    @property
    def warp(self) -> np.ndarray:
        """The per-block time warps ``(n_blocks, n_frames + 1)`` (a copy)."""
        return self._warp.copy()

    @property
    def labels(self) -> np.ndarray:
        """Block index of every output pixel ``(H, W)`` (a copy)."""
        return self._labels.copy()

    @property
    def rate_map(self) -> np.ndarray | None:
        """The rate map as set (before smoothing), or None for uniform rate 1."""
        return None if self._rate_raw is None else self._rate_raw.copy()

    @rate_map.setter
    def rate_map(self, value: np.ndarray | None) -> None:
        self._rate_raw = None if value is None else check_rate_map(value, self._shape[:2])
        self._update_rate()

    @property
    def rate_sigma(self) -> float:
        return self._rate_sigma

    @rate_sigma.setter
    def rate_sigma(self, value: float) -> None:
        self._rate_sigma = check_float("rate_sigma", value, 0.0, MAX_SIGMA)
        self._update_rate()

    @property
    def effective_rate(self) -> np.ndarray:
        """The rate map the frames use (smoothed, quantized to 1/512), ``(H, W)`` float32; ones when none is set."""
        return np.ones(self._shape[:2], np.float32) if self._rate is None else self._rate.copy()

    def _update_rate(self) -> None:
        if self._rate_raw is None:
            self._rate = None
            if self.backend == "opencl":
                self._set_runs(None)
            return
        rate = self._rate_raw
        if self._rate_sigma > 0:
            rate = gaussian_smooth(rate, self._rate_sigma)
        self._rate = quantize_rate(rate)
        if self.backend == "opencl":
            self._set_runs(self._rate)

    # -- frames -----------------------------------------------------------------------------------
    def source_times(self, t: float | None = None) -> np.ndarray:
        """Per-pixel source time ``(H, W)`` float32 of the primary source at clock ``t`` (default: the next frame's)."""
        t = self._clock if t is None else check_float("t", t, -1e7, 1e7)
        tau = self._local_time(np.float32(t))
        return warp_time(self._warp, self._labels, tau)

    def _local_time(self, t: np.float32) -> np.ndarray:
        tau = np.full(self._shape[:2], t, np.float32) if self._rate is None else (t * self._rate).astype(np.float32)
        return fold_time(tau, self.n_frames, self._end)

    def _start(self, out: np.ndarray):
        event = self._draw(self._clock, out, wait=False)
        self._clock += self._speed
        return event

    def render_at(self, t: float, out: np.ndarray | None = None) -> np.ndarray:
        """The frame at clock ``t`` without moving the clock."""
        t = check_float("t", t, -1e7, 1e7)
        if out is None:
            out = np.empty(self._shape, np.uint8)
        self._draw(t, out)
        return out

    def render_reference(self, t: float, out: np.ndarray | None = None) -> np.ndarray:
        """The numpy reference of a frame at clock ``t`` (works with either backend)."""
        tau = self._local_time(np.float32(t))
        v = _sample(self._flat, self._pix, warp_time(self._warp, self._labels, tau), self._end, self.interpolate)
        if self._blend:
            sel = self._wq > 0
            t2 = warp_time(self._warp, self._labels2[sel], tau[sel])
            v2 = _sample(self._flat, self._pix2[sel], t2, self._end, self.interpolate)
            a = (self._wq[sel].astype(np.float32) * np.float32(1.0 / 256.0))[:, None]
            v[sel] = v[sel] + a * (v2 - v[sel])
        if self._gain is not None:
            v = v * self._gain
        res = np.clip(np.rint(v), 0, 255).astype(np.uint8)
        if out is None:
            return res
        out[...] = res
        return out

    def _draw(self, t: float, out: np.ndarray, *, wait: bool = True):
        """The frame at clock ``t`` into ``out``; None once there, or (``wait=False``) the event after which it is."""
        if self.backend == "numpy":
            self.render_reference(t, out)
            return None
        self._upload_block_frames(t)
        return self._out.launch(out, self._gsize, wait=wait)

    def _launch(self, t: float):
        """Enqueue the kernel for clock ``t`` into the device buffer alone and return its event
        (the benchmarks time it)."""
        self._upload_block_frames(t)
        return self._out.launch_on_device(self._gsize)

    def _upload_block_frames(self, t: float) -> None:
        import pyopencl as cl
        # a copy, since the previous frame's upload may still wait in the queue; the event is
        # kept because dropping it would wait for the copy (and the frame before it)
        self._bframe_upload = cl.enqueue_copy(self.queue, self._d_bframe, self._block_frames(t).copy(),
                                              is_blocking=False)

    def _block_frames(self, t: float) -> np.ndarray:
        """Per time slot (a rate and a block, see :meth:`_set_runs`), the source time at
        clock ``t`` as the kernel reads it: the byte offsets of its two frames and the
        fraction (the float32 formulas of :func:`fold_time`, :func:`warp_time` and :func:`_sample`)."""
        t32 = np.float32(t)
        if self._pair_rate is None:
            tau = fold_time(np.full(1, t32, np.float32), self.n_frames, self._end)
        else:
            tau = fold_time(t32 * self._pair_rate, self.n_frames, self._end)
        k = np.clip(np.floor(tau).astype(np.int64), 0, self.n_frames - 1)
        fr = (tau - k.astype(np.float32)).astype(np.float32)
        w0 = self._warp_t[k, self._pair_block]
        s = w0 + fr * (self._warp_t[k + 1, self._pair_block] - w0)
        si = np.floor(s)
        i0 = si.astype(np.int32)
        n, fb = self.n_frames, self._flat.shape[1] * 3
        i1 = i0 + 1
        if self._end == "loop":
            i0 = np.where(i0 >= n, i0 - n, i0)
            i1 = np.where(i1 >= n, i1 - n, i1)
        else:
            i0 = np.minimum(i0, n - 1)
            i1 = np.minimum(i1, n - 1)
        b = self._bframe
        b[:, 0] = i0 * fb
        b[:, 1] = (i1 if self.interpolate else i0) * fb
        b[:, 2] = (s - si).astype(np.float32).view(np.int32)
        return b

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a frame moves at least: what the kernel reads (run tables, the time slots,
        blend codes, gain, source pixels: two frames per source when interpolating), the
        output written (and copied to the caller unless written into its array directly). For the
        numpy backend, per-pixel maps as packed device tables (source, label, rate) instead."""
        h, w = self._shape[:2]
        px = h * w
        per_src = 2 if self.interpolate else 1
        gain = 12 * px if self._gain is not None else 0
        if self.backend == "numpy":
            maps = px * (4 + (2 if self.n_blocks <= 0xFFFF else 4) + (4 if self._rate is not None else 0))
            return int(maps + gain + per_src * 3 * px + 6 * px)
        src = per_src * (3 * px + self._n_blend_bytes)
        out = 3 * px if self.direct else 6 * px
        return int(32 * self.n_runs + 16 * len(self._pair_block) + 2 * self._n_blend_bytes + gain + src + out)

    # -- state --------------------------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {"clock": self._clock, "speed": self._speed, "end": self._end, "jitter": self._jitter,
                "seed": self.seed, "rate_map": self.rate_map, "rate_sigma": self._rate_sigma}

    def _set_state(self, state: dict[str, Any]) -> None:
        seed = check_seed("state seed", state["seed"])
        clock = check_float("state clock", state["clock"], -1e7, 1e7)
        self.speed = state["speed"]
        self.rate_sigma = state["rate_sigma"]
        self.rate_map = state["rate_map"]
        end = state["end"]
        if end not in ENDS:
            raise ValueError(f"state end must be one of {ENDS}, not {end!r}")
        jitter = check_float("state jitter", state["jitter"], 0.0, float(self.n_frames))
        self.seed, self._end, self._jitter = seed, end, jitter
        self._make_warp()
        self._clock = clock
