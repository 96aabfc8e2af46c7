"""Mode ``evolve``: time-varying textures (rust spreading, honey melting) played from a quilt.

The analyzer's quilt says, for every output pixel, which source pixel it copies and which
placed block it belongs to. Frame ``t`` is a gather from the stored source frames through
that map, at a per-pixel source time built in three steps:

1. **rate map** ``M(y, x)``: local time ``tau = t * M`` (the seed's eq. 8), so brighter
   regions of ``M`` evolve faster; ``M`` may be Gaussian-smoothed so that regions of
   different rate meet without a seam;
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
gathering pixel by pixel; the host computes each block's source frames once per frame. The shared gather machinery (:mod:`.gather`) supplies
the packing of source entries and the Gaussian smoothing; its kernel adds a per-pixel
*offset* to one global time, which cannot express a per-pixel rate times the time or a
per-block time warp without re-uploading a full time map every frame, hence the own kernel.
"""
from __future__ import annotations

import os
from typing import Any, Sequence

import numpy as np

from ..tiledb import QuiltModel, TileDB
from .base import Player, check_float, check_seed
from .gather import gaussian_smooth
from .ratemap import check_rate_map

ENDS = ("hold", "loop", "pingpong")
SPEED_RANGE = (-16.0, 16.0)
MAX_SIGMA = 1024.0
SPILL = 16           # bytes a kernel chunk may read past a run
MAX_CLASSES = 8      # distinct rates of runs with a constant rate that get per-frame host tables
_END_CODE = {"hold": 0, "loop": 1, "pingpong": 2}


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


def _merge_plain(key_a, key_b, swap, key_p):
    """Fold each plain run into a neighbouring band of its row (the previous one, else the
    next) whose stream pair holds its stream."""
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
    key_a, key_b, swap = key_a.copy(), key_b.copy(), swap.copy()
    key_a[moved] = ka[tgt[moved]]
    key_b[moved] = kb[tgt[moved]]
    swap[moved] = key_p[moved] == key_b[moved]
    return key_a, key_b, swap


def build_runs(pix: np.ndarray, labels: np.ndarray, wq: np.ndarray | None = None,
               pix2: np.ndarray | None = None, labels2: np.ndarray | None = None, *,
               merge: bool = True) -> dict[str, np.ndarray]:
    """Cut the quilt's rows into runs, the unit of work of kernel ``evolve``.

    A *stream* is one block's source at a constant offset along a row (source pixel =
    output column + offset). A run is a maximal segment of one row that reads one stream
    (plain: no cross-fade) or one unordered pair of streams (a cross-fade band, which keeps
    its pair on both sides of the cut, where the primary and second sources swap). With
    ``merge`` (default), a plain run next to a band of its row whose pair holds its stream
    joins that band, its pixels blending with weight 0 (exactly the plain value): fewer,
    longer runs, which the kernel does faster than more, shorter ones.

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
        key_a, key_b, swap = _merge_plain(key_a, key_b, swap, key_p)
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


class EvolvePlayer(Player):
    """Endless frames of a time-varying texture from its ``quilt`` and stored frames.

    Parameters
    ----------
    db : path or TileDB
        The tile database (the texture needs ``quilt`` data and stored frames).
    texture : str, optional
        Texture name (optional when the database holds one texture).
    backend : {"opencl", "numpy"}
        ``"numpy"`` is the reference implementation and the fallback without OpenCL.
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
        Per-pixel rate ``M``; see :mod:`dynatex.player.ratemap` for generators.
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
                 backend: str = "opencl", device: str | None = None, seed: int = 0,
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
        if self.backend == "opencl":
            self._setup_opencl(frames)

    def _setup_opencl(self, frames: np.ndarray) -> None:
        import pyopencl as cl
        from .opencl import build_program
        h, w = self._shape[:2]
        mf = cl.mem_flags
        ro = mf.READ_ONLY | mf.COPY_HOST_PTR
        if self._blend:
            runs = build_runs(self._pix, self._labels, self._wq, self._pix2, self._labels2)
        else:
            runs = build_runs(self._pix, self._labels)
        self._run_starts, self._n_blend_bytes = runs["starts"], int(3 * runs["lengths"][runs["runs"][:, 3] < 0].sum())
        self.n_runs = len(runs["starts"])
        pad = np.zeros(SPILL, np.uint8)   # a spilling chunk may read past the ends (values unused)
        self._d_stack = cl.Buffer(self.ctx, ro, hostbuf=np.concatenate([frames.reshape(-1), pad]))
        self._d_runs = cl.Buffer(self.ctx, ro, hostbuf=runs["runs"])
        self._d_runs_b = cl.Buffer(self.ctx, ro, hostbuf=runs["runs_b"])
        self._d_row_start = cl.Buffer(self.ctx, ro, hostbuf=runs["row_start"])
        self._d_code = cl.Buffer(self.ctx, ro, hostbuf=np.concatenate([runs["code"], np.zeros(SPILL, np.uint16)]))
        gain = np.zeros(4, np.float32) if self._gain is None else self._gain.reshape(-1)
        self._d_gain = cl.Buffer(self.ctx, ro, hostbuf=np.concatenate([gain, np.zeros(SPILL, np.float32)]))
        self._d_rate = cl.Buffer(self.ctx, mf.READ_ONLY, h * w * 4)
        self._d_run_class = cl.Buffer(self.ctx, mf.READ_ONLY, self.n_runs * 4)
        self._d_warp = cl.Buffer(self.ctx, mf.READ_ONLY, self._warp.nbytes)
        self._class_rates = np.ones(1, np.float32)       # rate classes (uniform: one class, rate 1)
        self._bframe = np.zeros((1, self.n_blocks, 4), np.int32)    # grows with the rate classes
        self._d_bframe = cl.Buffer(self.ctx, mf.READ_ONLY, self._bframe.nbytes)
        self._d_out = cl.Buffer(self.ctx, mf.WRITE_ONLY, h * w * 3)
        self.device_bytes = int(frames.nbytes + sum(runs[k].nbytes for k in ("runs", "runs_b", "row_start", "code"))
                                + (self._gain.nbytes if self._gain is not None else 0) + h * w * 7 + self.n_runs * 4
                                + self._warp.nbytes + self._bframe.nbytes)
        defines = {"FRAME_BYTES": self._flat.shape[1] * 3, "NFRAMES": self.n_frames, "KNOTS": self.n_frames + 1,
                   "INTERP": self.interpolate, "GAIN": self._gain is not None, "NBLOCKS": self.n_blocks}
        self._kernels = {}
        for rate in (False, True):
            for end in ENDS:
                k = build_program(self.ctx, "quilt.cl", {**defines, "RATE": rate, "END": _END_CODE[end]}).kernel("evolve")
                k.set_args(self._d_stack, self._d_runs, self._d_runs_b, self._d_row_start, self._d_code,
                           self._d_rate, self._d_run_class, self._d_warp, self._d_bframe, self._d_gain, self._d_out,
                           np.int32(h), np.float32(0))
                self._kernels[rate, end] = k
        self._gsize = (h,)
        self._upload_warp()

    def _upload_rate(self, rate: np.ndarray) -> None:
        """The per-pixel rate map and the runs' rate classes: a run along which the rate is
        constant gets the class of its rate (the ``MAX_CLASSES`` rates that cover the most
        runs), so that the host computes its streams' frames once per frame and block;
        the other runs (-1) take the per-pixel path."""
        import pyopencl as cl
        flat = rate.reshape(-1)
        lo = np.minimum.reduceat(flat, self._run_starts)
        hi = np.maximum.reduceat(flat, self._run_starts)
        const = lo == hi
        values, inverse, counts = np.unique(lo[const], return_inverse=True, return_counts=True)
        keep = np.argsort(-counts, kind="stable")[:MAX_CLASSES]
        index = np.full(len(values), -1, np.int32)
        index[keep] = np.arange(len(keep), dtype=np.int32)
        run_class = np.full(len(lo), -1, np.int32)
        run_class[const] = index[inverse]
        self._n_varying_px = int(np.diff(np.append(self._run_starts, flat.size))[run_class < 0].sum())
        self._class_rates = np.ascontiguousarray(values[keep], np.float32)
        if len(keep) > len(self._bframe):
            self._bframe = np.zeros((len(keep), self.n_blocks, 4), np.int32)
            self._d_bframe = cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY, self._bframe.nbytes)
            for k in self._kernels.values():
                k.set_arg(8, self._d_bframe)
        cl.enqueue_copy(self.queue, self._d_rate, np.ascontiguousarray(flat), is_blocking=True)
        cl.enqueue_copy(self.queue, self._d_run_class, run_class, is_blocking=True)

    def _upload_warp(self) -> None:
        self._warp_t = np.ascontiguousarray(self._warp.T)     # (knots, blocks): one row per local time
        if self.backend == "opencl":
            import pyopencl as cl
            cl.enqueue_copy(self.queue, self._d_warp, self._warp, is_blocking=True)

    def _warm(self) -> None:
        scratch = np.empty(self._shape, np.uint8)
        if self.backend == "opencl":
            saved = self._rate
            if saved is None:   # fill the rate buffers once so the RATE variant can run
                self._upload_rate(np.ones(self._shape[:2], np.float32))
            end = self._end
            for rate in (False, True):
                for self._end in ENDS:
                    self._rate = np.ones(1, np.float32) if rate else None
                    self._draw(0.0, scratch)
            self._rate, self._end = saved, end
            if saved is not None:
                self._upload_rate(saved)
        else:
            self._draw(0.0, scratch)

    # -- controls ---------------------------------------------------------------------------------
    @property
    def speed(self) -> float:
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        self._speed = check_float("speed", value, *SPEED_RANGE)

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
        self._upload_warp()

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
        """The rate map the frames use (smoothed), ``(H, W)`` float32; ones when none is set."""
        return np.ones(self._shape[:2], np.float32) if self._rate is None else self._rate.copy()

    def _update_rate(self) -> None:
        if self._rate_raw is None:
            self._rate = None
            return
        rate = self._rate_raw
        if self._rate_sigma > 0:
            rate = np.ascontiguousarray(gaussian_smooth(rate, self._rate_sigma), np.float32)
        self._rate = rate
        if self.backend == "opencl":
            self._upload_rate(rate)

    # -- frames -----------------------------------------------------------------------------------
    def source_times(self, t: float | None = None) -> np.ndarray:
        """Per-pixel source time ``(H, W)`` float32 of the primary source at clock ``t`` (default: the next frame's)."""
        t = self._clock if t is None else check_float("t", t, -1e7, 1e7)
        tau = self._local_time(np.float32(t))
        return warp_time(self._warp, self._labels, tau)

    def _local_time(self, t: np.float32) -> np.ndarray:
        tau = np.full(self._shape[:2], t, np.float32) if self._rate is None else (t * self._rate).astype(np.float32)
        return fold_time(tau, self.n_frames, self._end)

    def _render(self, out: np.ndarray) -> None:
        self._draw(self._clock, out)
        self._clock += self._speed

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

    def _draw(self, t: float, out: np.ndarray) -> None:
        if self.backend == "numpy":
            self.render_reference(t, out)
            return
        import pyopencl as cl
        self._launch(t)
        cl.enqueue_copy(self.queue, out.reshape(-1), self._d_out, is_blocking=True)

    def _launch(self, t: float) -> None:
        """Enqueue the kernel for clock ``t`` (the frame lands in the device buffer; benchmarks time it alone)."""
        import pyopencl as cl
        k = self._kernels[self._rate is not None, self._end]
        if len(self._class_rates) or self._rate is None:
            cl.enqueue_copy(self.queue, self._d_bframe, self._block_frames(t), is_blocking=False)
        k.set_arg(12, np.float32(t))
        cl.enqueue_nd_range_kernel(self.queue, k, self._gsize, None)

    def _block_frames(self, t: float) -> np.ndarray:
        """Per rate class and block, the source time at clock ``t`` as the kernel reads it:
        the byte offsets of its two frames and the fraction (the float32 formulas of
        :func:`fold_time`, :func:`warp_time` and :func:`_sample`; one local time per class)."""
        t32 = np.float32(t)
        if self._rate is None:
            tau = fold_time(np.full(1, t32, np.float32), self.n_frames, self._end)
        else:
            tau = fold_time(t32 * self._class_rates, self.n_frames, self._end)
        k = np.clip(np.floor(tau).astype(np.int64), 0, self.n_frames - 1)
        fr = (tau - k.astype(np.float32)).astype(np.float32)[:, None]
        w0 = self._warp_t[k]
        s = w0 + fr * (self._warp_t[k + 1] - w0)
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
        b = self._bframe[:len(tau)]
        b[..., 0] = i0 * fb
        b[..., 1] = (i1 if self.interpolate else i0) * fb
        b[..., 2] = (s - si).astype(np.float32).view(np.int32)
        return b

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a frame moves at least: what the kernel reads (run tables, blend codes, gain,
        per-pixel rates where the rate varies along a run, source pixels: two frames per
        source when interpolating), the output written and copied to the caller. For the
        numpy backend, per-pixel maps as packed device tables (source, label, rate) instead."""
        h, w = self._shape[:2]
        px = h * w
        per_src = 2 if self.interpolate else 1
        gain = 12 * px if self._gain is not None else 0
        if self.backend == "numpy":
            maps = px * (4 + (2 if self.n_blocks <= 0xFFFF else 4) + (4 if self._rate is not None else 0))
            return int(maps + gain + per_src * 3 * px + 6 * px)
        rate = 0 if self._rate is None else 4 * self.n_runs + 4 * self._n_varying_px
        src = per_src * (3 * px + self._n_blend_bytes)
        return int(24 * self.n_runs + 2 * self._n_blend_bytes + rate + gain + src + 6 * px)

    # -- state --------------------------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {"clock": self._clock, "speed": self._speed, "end": self._end, "jitter": self._jitter,
                "seed": self.seed, "rate_map": self.rate_map, "rate_sigma": self._rate_sigma}

    def _set_state(self, state: dict[str, Any]) -> None:
        try:
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
        except KeyError as exc:
            raise ValueError(f"state lacks {exc.args[0]!r}") from None
        self._clock = clock
