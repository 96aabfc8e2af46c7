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
The player is the time model (clock, controls, the functions below); the runs engine
(:mod:`dynatex.player.engines.runs`: OpenCL kernel ``kernels/runs.cl`` or its numpy reference) draws the frames
from the quilt's maps at the source times the model gives it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import MAX_COUNT, MAX_SIDE, Choice, Flag, NpyFile, Range, Size, check_float, check_seed, check_size
from ...errors import InvalidArgumentError
from ...params import Param
from ...tiledb import QuiltModel
from ..base import Player
from ..controls import Capabilities, Control
from ..engines import open_engine
from ..engines.gather import gaussian_smooth
from ..engines.runs import quantize_rate
from .ratemap import check_rate_map

ENDS = ("hold", "loop", "pingpong")
SPEED_RANGE = (-16.0, 16.0)
MAX_SIGMA = 1024.0


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
        raise InvalidArgumentError(f"end must be one of {ENDS}, not {end!r}")
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
            dev = np.where(np.abs(step) <= bound[i], step, dev)  # the seed: d = 0 if it would leave the band
            dev = np.clip(dev, -bound[i], bound[i])  # the taper pulls back by at most 1 a step
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


class EvolvePlayer(Player):
    """Endless frames of a time-varying texture from its ``quilt`` and stored frames.

    The clock (:attr:`time`, in source frames at rate 1; assign to seek) is part of the state.
    The rate map is played quantized to steps of 1/512 after smoothing (:func:`quantize_rate`);
    :mod:`dynatex.player.modes.ratemap` makes rate maps.

    Examples
    --------
    >>> with EvolvePlayer("rust.h5", jitter=4, end="loop") as p:     # doctest: +SKIP
    ...     p.rate_map = ratemap.halves((p.shape[0], p.shape[1]), 2.0, 1.0)
    ...     frame = p.next_frame()
    """

    mode = "evolve"
    method = "quilt"
    options = (
        Param(
            "size",
            Size(MAX_SIDE),
            None,
            "Output size; must equal the stored quilt's canvas (re-run the analysis "
            "with another size for another canvas).",
            optional=True,
            default_doc="the quilt's",
        ),
        Param(
            "interpolate",
            Flag(),
            True,
            "Blend linearly between source frames at fractional times (otherwise the earlier frame).",
        ),
    )
    capabilities = Capabilities(needs_frames=True)

    def _open(
        self,
        *,
        seed: int,
        size: Sequence[int] | None,
        interpolate: bool,
        jitter: float = 0.0,
        end: str = "hold",
        speed: float = 1.0,
        rate_map: np.ndarray | None = None,
        rate_sigma: float = 0.0,
    ) -> None:
        self._setup(self.texture.read(self.method), seed, size, bool(interpolate))
        self.speed = speed
        self.end = end
        self.jitter = jitter
        self.rate_sigma = rate_sigma
        self.rate_map = rate_map
        self._warm()

    # -- setup ---------------------------------------------------------------------------------
    def _setup(self, model: QuiltModel, seed: int, size, interpolate: bool) -> None:
        h, w = model.size
        wanted = None if size is None else check_size("size", size, MAX_SIDE)
        if wanted is not None and wanted != (h, w):
            raise InvalidArgumentError(
                f"size {wanted} does not fit the stored quilt, whose canvas (height, width) is "
                f"{(h, w)}; re-run the analysis with that size (dynatex analyze --quilt-size)"
            )
        self.seed = check_seed("seed", seed)
        self.model_info = dict(model.info)
        self.interpolate = interpolate
        self._shape = (h, w, self.format.bytes)
        self.n_blocks = model.n_blocks
        src = self.texture.source
        frames = self.texture.frames().read()
        if frames.shape[-1] == 1:
            frames = np.repeat(frames, 3, axis=-1)
        self.n_frames = int(frames.shape[0])
        flat = np.ascontiguousarray(frames.reshape(self.n_frames, -1, 3))
        sw = src.width
        pix = model.source_map[..., 0].astype(np.int64) * sw + model.source_map[..., 1]
        self._labels = np.ascontiguousarray(model.labels, np.int64)
        blend = None
        if model.blend_weight is not None:
            blend = (
                np.rint(model.blend_weight.astype(np.float64) * 256).astype(np.int64),
                model.blend_map[..., 0].astype(np.int64) * sw + model.blend_map[..., 1],
                np.ascontiguousarray(model.blend_labels, np.int64),
            )
        gain = None if model.gain is None else np.ascontiguousarray(model.gain, np.float32)
        if gain is not None and gain.shape[2] == 1:
            gain = np.ascontiguousarray(np.repeat(gain, 3, axis=2))
        self._clock = 0.0
        self._rate_raw: np.ndarray | None = None
        self._rate: np.ndarray | None = None
        self._rate_sigma = 0.0
        self._warp = jitter_warp(self.n_blocks, self.n_frames, 0.0, seed=self.seed)
        self.engine = open_engine(
            "runs",
            flat,
            (h, w),
            pix,
            self._labels,
            n_blocks=self.n_blocks,
            blend=blend,
            gain=gain,
            interpolate=interpolate,
            ctx=self.ctx,
            queue=self.queue,
            format=self.format,
        )
        self._reference = None

    def _warm(self) -> None:
        self._draw(0.0, np.empty(self._shape, np.uint8))

    # -- controls ---------------------------------------------------------------------------------
    speed = Control(Range(float, *SPEED_RANGE), 1.0, "Source frames the clock advances per output frame.")
    end = Control(
        Choice(*ENDS), "hold", "After the last source frame: hold it, loop to the first, or play back and forth."
    )

    @end.setter
    def end(self, value: str) -> None:
        if value != self._end:
            self._end = value
            self._make_warp()

    jitter = Control(
        Range(float, 0.0, MAX_COUNT),
        0.0,
        "Per-block time jitter e: the largest deviation of a "
        "block's time from the true time, frames, at most the clip's frames.",
    )

    @jitter.setter
    def jitter(self, value: float) -> None:
        v = check_float("jitter", value, 0.0, float(self.n_frames))
        if v != self._jitter:
            self._jitter = v
            self._make_warp()

    rate_map = Control(
        NpyFile(),
        None,
        "Per-pixel rate of evolution M, (H, W) in [0, 64] (local time t * M); see "
        "dynatex.player.modes.ratemap for generators.",
        flag=None,
        optional=True,
        default_doc="uniform 1",
    )

    @rate_map.setter
    def rate_map(self, value: np.ndarray | None) -> None:
        self._rate_raw = None if value is None else check_rate_map(value, self._shape[:2])
        self._update_rate()

    @rate_map.getter
    def rate_map(self) -> np.ndarray | None:
        return None if self._rate_raw is None else self._rate_raw.copy()

    rate_sigma = Control(
        Range(float, 0.0, MAX_SIGMA), 0.0, "Gaussian smoothing of the rate map, output pixels (0: none)."
    )

    @rate_sigma.setter
    def rate_sigma(self, value: float) -> None:
        self._rate_sigma = value
        self._update_rate()

    @property
    def time(self) -> float:
        """The clock, in source frames at rate 1 (the next frame shows this time)."""
        return self._clock

    @time.setter
    def time(self, value: float) -> None:
        self._clock = check_float("time", value, -1e7, 1e7)

    def _on_reseed(self) -> None:
        """A new seed draws new jitter warps."""
        self._make_warp()

    def _make_warp(self) -> None:
        self._warp = jitter_warp(self.n_blocks, self.n_frames, self._jitter, end=self._end, seed=self.seed)

    @property
    def warp(self) -> np.ndarray:
        """The per-block time warps ``(n_blocks, n_frames + 1)`` (a copy)."""
        return self._warp.copy()

    @property
    def labels(self) -> np.ndarray:
        """Block index of every output pixel ``(H, W)`` (a copy)."""
        return self._labels.copy()

    @property
    def effective_rate(self) -> np.ndarray:
        """The rate map the frames use (smoothed, quantized to 1/512), ``(H, W)`` float32; ones when none is set."""
        return np.ones(self._shape[:2], np.float32) if self._rate is None else self._rate.copy()

    def _update_rate(self) -> None:
        if self._rate_raw is None:
            self._rate = None
        else:
            rate = self._rate_raw
            if self._rate_sigma > 0:
                rate = gaussian_smooth(rate, self._rate_sigma)
            self._rate = quantize_rate(rate)
        self.engine.set_rate(self._rate)
        if self._reference is not None:
            self._reference.set_rate(self._rate)

    # -- frames -----------------------------------------------------------------------------------
    def source_times(self, t: float | None = None) -> np.ndarray:
        """Per-pixel source time ``(H, W)`` float32 of the primary source at clock ``t`` (default: the next frame's)."""
        t = self._clock if t is None else check_float("t", t, -1e7, 1e7)
        return self._source_time(self._rate, self._labels, np.float32(t))

    def _source_time(self, rate: np.ndarray | None, blocks: np.ndarray, t: np.float32) -> np.ndarray:
        """Source times of ``blocks`` at clock ``t`` and ``rate`` (None: 1), the engines' time model:
        local time ``t * rate`` folded by the end mode, then the block's jitter warp."""
        tau = np.full(blocks.shape, t, np.float32) if rate is None else (t * rate).astype(np.float32)
        return warp_time(self._warp, blocks, fold_time(tau, self.n_frames, self._end))

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
        if self._reference is None:
            e = self.engine
            self._reference = open_engine(
                "runs",
                e.flat,
                e.shape,
                e.pix,
                e.labels,
                n_blocks=e.n_blocks,
                blend=e.blend,
                gain=e.gain,
                interpolate=e.interpolate,
                format=e.format,
            )
            self._reference.set_rate(self._rate)
        if out is None:
            out = np.empty(self._shape, np.uint8)
        self._reference.draw(
            out, check_float("t", t, -1e7, 1e7), source_time=self._source_time, loop=self._end == "loop"
        )
        return out

    def _draw(self, t: float, out: np.ndarray, *, wait: bool = True):
        """The frame at clock ``t`` into ``out``; None once there, or (``wait=False``) the event after which it is."""
        return self.engine.draw(out, t, source_time=self._source_time, loop=self._end == "loop", wait=wait)

    @property
    def still_after(self) -> int | None:
        """With ``end="hold"`` and a forward speed, the frames until the clock (rate map aside)
        reaches the last source frame, plus one frame of the held end; else None."""
        if self.end == "hold" and self.speed > 0:
            return math.ceil((self.n_frames - 1) / self.speed) + 1
        return None

    @property
    def n_runs(self) -> int | None:
        """Runs the OpenCL engine cuts the quilt into (None for the numpy reference)."""
        return getattr(self.engine, "n_runs", None)

    @property
    def bytes_per_frame(self) -> int:
        """Bytes a frame moves at least (see the engine's ``bytes_per_frame``)."""
        return self.engine.bytes_per_frame

    # -- state --------------------------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {"clock": self._clock, "seed": self.seed}

    def _set_state(self, state: dict[str, Any]) -> None:
        seed = check_seed("state seed", state["seed"])
        clock = check_float("state clock", state["clock"], -1e7, 1e7)
        if state["rate_map"] is not None:
            check_rate_map(state["rate_map"], self._shape[:2], name="state rate_map")
        jitter = check_float("state jitter", state["jitter"], 0.0, float(self.n_frames))
        self.seed, self._end, self._jitter, self._clock = seed, state["end"], jitter, clock
        self._make_warp()
