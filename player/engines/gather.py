"""Shared gather machinery: output pixel = stored frame stack sampled at a per-pixel source
position and a per-pixel time, blended linearly in time, colour-toned.

Mode ``tiles`` (and any mode that copies stored pixels at per-pixel times) draws through
a gather engine (:func:`open_gather`). The OpenCL engine owns the device buffers of one
frame stack and of the maps that say where and when every output pixel reads, builds
``kernels/gather.cl`` once at construction, and renders a frame with one kernel launch
into the caller's array (or a device buffer copied into it). Every device path has a numpy
reference (the ``numpy`` backend runs exactly those functions), and tests compare the two.

The pieces
----------
frame stack
    ``(N, h, w, 3)`` uint8: ``N`` stored frames (tiles side by side, ...). A source pixel is
    the linear index ``y * w + x`` inside one frame.
source
    Either a per-pixel map (:meth:`Gather.set_source_map`, ``(H, W)`` packed int32) or,
    when the Gather is built with ``cell=(ch, cw)``, a grid of cells
    (:meth:`Gather.set_source_grid`: ``(ceil(H/ch), ceil(W/cw))`` packed int32 naming each
    cell's top-left source pixel; the pixel at ``(dy, dx)`` inside a cell reads
    ``origin + dy * w + dx``; cheaper: no per-pixel map is read). A packed entry is
    ``(tone << 24) | (y * w + x)`` (:func:`pack_source`), so a frame may hold at most
    2**24 pixels and there are at most 256 tones.
time
    ``time(y, x) = t + map(y, x)`` where ``t`` is the argument of :meth:`Gather.render`
    and ``map`` is the time map (:meth:`Gather.set_time_map`), given per pixel
    (``step=1``) or on a coarser lattice sampled bilinearly (``step=s``: shape
    ``(ceil(H/s), ceil(W/s))``, sample ``(i, j)`` sits at pixel centre ``((i+0.5)s-0.5, ...)``).
    A second map, the target, may be given with it: ``render(t, fade=f)`` then uses
    ``map + f (target - map)``, faded on the device (a player moving between two maps
    uploads them once, not every frame; :meth:`Gather.next_time_map` moves the target in as
    the map and uploads only the new target). Frame indices wrap by ``wrap`` (``"loop"``: modulo
    ``N``; ``"clamp"``: held at the ends; ``"pingpong"``: forth and back with period
    ``2(N-1)``). With ``interpolate`` the pixel is ``(1-f) F[wrap(i)] + f F[wrap(i+1)]``,
    ``i = floor(time)``, ``f = time - i``. :meth:`Gather.smooth_time_map` Gaussian-smooths
    the maps in place (separable, edges clamped, ``sigma`` in output pixels).
tone
    ``out = round(v * gain[tone] + offset[tone])`` saturated to 0..255 per channel
    (:meth:`Gather.set_tones`, tables ``(n, 3)``; tone 0 defaults to identity).

Numerical contract: time, blend and tone are computed in integers, the same integers on the
device and in the numpy reference (:func:`time_units`, :func:`gather_reference`; the
tests compare every pixel for equality). Time: each map sample is rounded once to 4080ths
(255 x 16) of a frame past ``floor(t)`` (float32, no contracted multiply-adds), the
bilinear sampling runs in integers (halves of a step), and a pixel's time comes out in
255ths of a frame: frame ``i`` and weight ``w`` in [0, 255) of the next frame, within
1/255 of a frame of the real-valued interpolation. Blend and tone:
``v = (255 - w) (a - 128) + w (b - 128)``, gain ``G = round(gain 2**17 / 255)``, offset
``O = round(2 (128 gain + offset)) + 1``, ``out = clip((((v G) >> 16) + O) >> 1, 0, 255)``:
every intermediate fits signed 16 bits for gains up to 63 (so the device works on 32 or 64
lanes at once, one multiply-add per pair of frames). The result is the rounding of the blend
at the quantised weight, gain and offset: within one grey level of the real-valued formula
for gains up to 1.5 (tested; the weight's error grows as ``|b - a| gain / 510``). Time maps
are limited to +-2048 frames (the integer time then fits 32 bits).

Device paths: the default kernel (kernels/gather.cl, portable OpenCL C) renders pixel by
pixel, RUN pixels of a row per work-item. On CPU devices where the self-test verified it,
``time_step=8`` uses the x86 variant (kernels/variants/gather_wide.cl, clang vector
extensions): a work-item renders a run of 64 pixels down several bands of 8 rows (a band:
the rows of one pair of map rows): a run whose source is linear (one cell, or two cells
split at a boundary and merged bytewise; a per-pixel map with consecutive pixels and one
tone) is blended and toned on 64-byte vectors in 16-bit lanes in every band whose frames
span at most seven neighbours, tone factors pre-expanded per byte on the host and set up
once per cell row; other bands go pixel by pixel with the same integers. The runs are
placed so that their stores are 64-byte aligned wherever the output's rows are a multiple
of 64 bytes long and the output starts on a 16-byte boundary (any numpy array): they are
then non-temporal, writing the frame once without reading it first. Where the device
shares host memory (PoCL on the CPU; probed once at open, :attr:`Gather.direct`) the kernel
writes straight into the caller's array: one launch, no copy.

Examples
--------
>>> import numpy as np
>>> from dynatex.player.engines.gather import open_gather, pack_source
>>> stack = np.random.default_rng(0).integers(0, 256, (8, 4, 6, 3), dtype=np.uint8)
>>> g = open_gather(stack, (4, 6), backend="numpy")
>>> g.set_source_map(pack_source(np.arange(24).reshape(4, 6)))   # identity map
>>> g.set_time_map(np.zeros((4, 6), np.float32))
>>> bool((g.render(3.0) == stack[3]).all())
True
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import MAX_SIDE, Size, check_float, check_int, check_out
from ...errors import ArgumentTypeError, InvalidArgumentError
from ..pixels import pixel_format
from . import BACKENDS
from .gather_reference import (
    MAX_FRAME_PIXELS,
    MAX_GAIN,
    MAX_OFFSET,
    MAX_TONES,
    WRAPS,
    fixed_tones,
    gather_reference,
    gaussian_smooth,
    gaussian_weights,
    source_indices,
    time_units,
    unpack_source,
    wrap_index,
)
from .gather_reference import (
    pack_source as pack_source,  # the packed maps' format, with the engine that reads them
)

log = logging.getLogger(__name__)
MAX_TIME = 2048.0  # |time map| in frames: the integer time (4080ths, x 256) fits 32 bits
RUN = 32  # output pixels per work-item of the per-pixel kernel (time steps other than 8)
STACK_PAD = 256  # bytes of padding around the device copy of the frame stack (a run's 192 bytes fit)
BANDS = 8  # wide variant: a work-item renders one run of 64 pixels on BANDS bands of 8 rows
TONE_STRIDE = 384  # int16 per device tone row: 192 gains then 192 offsets, per byte of a 64-pixel run
TONE_OB = 192
_WRAP_CODE = {"loop": 0, "clamp": 1, "pingpong": 2}
SIDES = Size(MAX_SIDE)  # out_size and cell: (height, width), each side in 1..MAX_SIDE
#: the bytes of a 64-pixel run in the order of the wide kernel's 16-bit lanes: per 64-byte
#: chunk, the low then the high half of the x86 byte interleave (bytes 0-7 of each 16-byte
#: lane, then 8-15)
_CHUNK_BYTES = np.array(
    [64 * c + 16 * lane + half + i for c in range(3) for half in (0, 8) for lane in range(4) for i in range(8)]
)


class Gather:
    """Render frames gathered from a frame stack (see the module docstring for the model).

    The interface of both gather engines, :class:`GatherOpenCL` and :class:`GatherReference`
    (:func:`open_gather` picks one): the checks, the host copies of sources, maps and tones,
    and the numpy reference of every frame (:meth:`render_reference`).

    Parameters
    ----------
    frames : (N, h, w, 3) uint8
        The stored frame stack (copied to the device once).
    out_size : (H, W)
        Output frame size.
    wrap : {"loop", "clamp", "pingpong"}
        How frame indices fold into ``[0, N)``. Fixed at construction (a kernel define).
    interpolate : bool
        Blend linearly between neighbouring frames (fixed at construction).
    time_step : int
        Lattice step of the time map in output pixels (fixed at construction).
    cell : (ch, cw), optional
        Source given as a grid of ``ch x cw`` cells (:meth:`set_source_grid`) instead of a
        per-pixel map (:meth:`set_source_map`). Fixed at construction (a kernel define).
    wide : bool, optional
        With ``time_step=8``, use the x86 variant ``kernels/variants/gather_wide.cl`` (True)
        or the portable kernel (False). Default: the variant where the device's self-test
        verified it (CPU devices whose compiler is clang), else the portable kernel. Both
        compute the same integers (see the module docstring); :attr:`wide` says which runs.
        ``wide=True`` on a device where the variant is not verified is an error. Both
        write every format straight into the output.
    format : {"RGB", "RGBA", "BGRA"}
        Output pixel format (:data:`~dynatex.player.pixels.FORMATS`); the stack stays RGB,
        the kernel places the bytes (and alpha, 255) as it writes them.

    After construction call :meth:`set_source_map` or :meth:`set_source_grid`, optionally
    :meth:`set_time_map` (default zeros), :meth:`smooth_time_map` and :meth:`set_tones`
    (default identity); then :meth:`render` as often as wanted. Maps and tones may be
    replaced between any two frames; nothing is rebuilt.

    Examples
    --------
    >>> import numpy as np
    >>> stack = np.zeros((4, 2, 2, 3), np.uint8); stack[:, :, :, 0] = np.arange(4)[:, None, None] * 10
    >>> g = open_gather(stack, (2, 2), backend="numpy", cell=(2, 2))
    >>> g.set_source_grid(pack_source(np.zeros((1, 1), int)))
    >>> int(g.render(1.5)[0, 0, 0])      # halfway between 10 and 20
    15
    """

    backend = ""

    def __init__(
        self,
        frames: np.ndarray,
        out_size: Sequence[int],
        *,
        wrap: str = "loop",
        interpolate: bool = True,
        time_step: int = 1,
        cell: Sequence[int] | None = None,
        wide: bool | None = None,
        format: str = "RGB",
    ) -> None:
        frames = np.asarray(frames)
        if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[3] != 3 or frames.shape[0] < 1:
            raise InvalidArgumentError(
                f"frames must be uint8 (N, h, w, 3) with N >= 1, not {frames.dtype} {frames.shape}"
            )
        if frames.shape[1] * frames.shape[2] > MAX_FRAME_PIXELS:
            raise InvalidArgumentError(
                f"frames hold {frames.shape[1] * frames.shape[2]} pixels each, more than {MAX_FRAME_PIXELS}"
            )
        if wrap not in WRAPS:
            raise InvalidArgumentError(f"wrap must be one of {WRAPS}, not {wrap!r}")
        h_out, w_out = SIDES.check("out_size", out_size)
        self.time_step = check_int("time_step", time_step, 1, 4096)
        if wide is not None and not isinstance(wide, (bool, np.bool_)):
            raise ArgumentTypeError(f"wide must be None, True or False, not {wide!r}")
        self._wide_choice = wide
        self.wrap, self.interpolate = wrap, bool(interpolate)
        self.n_frames, self.frame_h, self.frame_w = (int(v) for v in frames.shape[:3])
        self.cell = None if cell is None else SIDES.check("cell", cell)
        self.grid = self.cell is not None
        if self.grid and (self.cell[0] > self.frame_h or self.cell[1] > self.frame_w):
            raise InvalidArgumentError(
                f"cell {self.cell[0]}x{self.cell[1]} is larger than the stored {self.frame_h}x{self.frame_w} frame"
            )
        self.format = pixel_format(format)
        self.out_shape = (h_out, w_out, self.format.bytes)
        self.tmap_shape = (-(-h_out // self.time_step), -(-w_out // self.time_step))
        self._stack = np.array(frames, order="C")
        self._source: np.ndarray | None = None
        self._cell: tuple[int, int] | None = None
        self._tmap = np.zeros(self.tmap_shape, np.float32)
        self._target: np.ndarray | None = None  # the map the time map fades toward (set_time_map)
        self._tones = np.zeros((1, 6), np.float32)
        self._tones[0, :3] = 1.0
        self.direct = False  # frames written straight into the caller's array (OpenCL, set at open)
        self.wide = False  # the x86 variant renders (OpenCL, time step 8, verified on the device)
        self._last_t, self._last_fade = 0.0, 0.0

    # -- what an engine implements --------------------------------------------------------------
    def _upload_source(self) -> None:
        """Put :attr:`_source` where the frames are drawn (nothing to do in host memory)."""

    def _upload_tmap(self) -> None:
        """Put the time map and its target where the frames are drawn."""

    def _upload_tones(self) -> None:
        """Put the tone table where the frames are drawn."""

    def _maps(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The time map and its target as the frames use them."""
        return self._tmap, self._target

    def _smooth(self, sigma: float, weights: np.ndarray, target_only: bool = False) -> None:
        """Gaussian-smooth the maps (or the target alone) where they are kept (``sigma`` in map
        samples, its taps)."""
        raise NotImplementedError

    def _shift_tmap(self) -> None:
        """The target has become the time map and :attr:`_target` holds the new target: put it
        where the frames are drawn (the old target stays there as the map)."""

    def _launch(self, t: float, out: np.ndarray):
        """Start the frame at folded time ``t`` (fade: :attr:`_last_fade`) into ``out``; None or an event."""
        raise NotImplementedError

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for the reference)."""

    # -- inputs --------------------------------------------------------------------------------
    def set_source_map(self, packed: np.ndarray) -> None:
        """Per-pixel source: ``(H, W)`` int32 packed entries (:func:`pack_source`). Needs ``grid=False``."""
        if self.grid:
            raise InvalidArgumentError("this Gather was built with a cell grid; use set_source_grid")
        packed = self._check_packed("packed", packed, self.out_shape[:2])
        idx, _ = unpack_source(packed)
        if idx.size and idx.max() >= self.frame_w * self.frame_h:
            raise InvalidArgumentError(f"packed holds source pixels outside the {self.frame_h}x{self.frame_w} frame")
        self._store_source(packed, None)

    def set_source_grid(self, origins: np.ndarray) -> None:
        """Cell-grid source: ``origins`` ``(ceil(H/ch), ceil(W/cw))`` packed top-left pixels of each cell.

        Every cell must fit inside the stored frame: its top-left ``(y, x)`` needs
        ``y + ch <= h`` and ``x + cw <= w``. Needs ``cell`` at construction.
        """
        if not self.grid:
            raise InvalidArgumentError("this Gather was built without a cell; use set_source_map")
        ch, cw = self.cell
        h, w = self.out_shape[:2]
        origins = self._check_packed("origins", origins, (-(-h // ch), -(-w // cw)))
        idx, _ = unpack_source(origins)
        y, x = idx // self.frame_w, idx % self.frame_w
        if idx.size and ((y + ch > self.frame_h).any() or (x + cw > self.frame_w).any()):
            raise InvalidArgumentError("origins name cells that reach outside the stored frame")
        self._store_source(origins, (ch, cw))

    def _check_packed(self, name: str, packed: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        packed = np.asarray(packed)
        if packed.dtype != np.int32:
            raise ArgumentTypeError(f"{name} must be int32 packed entries (see pack_source), not {packed.dtype}")
        if packed.shape != tuple(shape):
            raise InvalidArgumentError(f"{name} must have shape {tuple(shape)}, not {packed.shape}")
        _, tone = unpack_source(packed)
        if tone.size and tone.max() >= len(self._tones):
            raise InvalidArgumentError(f"{name} names tone {int(tone.max())} but only {len(self._tones)} tones are set")
        return np.array(packed, order="C")

    def _store_source(self, packed: np.ndarray, cell: tuple[int, int] | None) -> None:
        self._source, self._cell = packed, cell
        self._upload_source()

    def set_time_map(self, tmap: np.ndarray, target: np.ndarray | None = None) -> None:
        """Time offsets in frames, ``tmap_shape`` float32, finite, within +-2048 frames.

        With ``target`` (same shape) the offsets fade toward it: :meth:`render` with ``fade``
        ``f`` uses ``tmap + f (target - tmap)``, faded on the device, so a caller that moves
        between two maps over many frames uploads them once.
        """
        maps = [self._check_tmap("tmap", tmap)]
        if target is not None:
            maps.append(self._check_tmap("target", target))
        self._tmap = maps[0]
        self._target = maps[1] if target is not None else None
        self._upload_tmap()

    def _check_tmap(self, name: str, tmap: np.ndarray) -> np.ndarray:
        tmap = np.asarray(tmap, np.float32)
        if tmap.shape != self.tmap_shape:
            raise InvalidArgumentError(f"{name} must have shape {self.tmap_shape}, not {tmap.shape}")
        if not np.isfinite(tmap).all():
            raise InvalidArgumentError(f"{name} must be finite")
        if tmap.size and np.abs(tmap).max() > MAX_TIME:
            raise InvalidArgumentError(
                f"{name} must lie within +-{MAX_TIME:g} frames, not {float(np.abs(tmap).max()):g}"
            )
        return np.array(tmap, np.float32, order="C")  # own copy: device reads land here

    @property
    def time_map(self) -> np.ndarray:
        """The current time map (after smoothing; a copy)."""
        return self._maps()[0].copy()

    @property
    def target_map(self) -> np.ndarray | None:
        """The map the time map fades toward, or None (see :meth:`set_time_map`; a copy)."""
        target = self._maps()[1]
        return None if target is None else target.copy()

    def smooth_time_map(self, sigma: float) -> None:
        """Gaussian-smooth the time map (and its target, if set) in place, ``sigma`` in output
        pixels (0: no change)."""
        self._smooth_maps(sigma, target_only=False)

    def next_time_map(self, target: np.ndarray, sigma: float = 0.0) -> None:
        """Move on one map: the target becomes the time map, and ``target`` (as in
        :meth:`set_time_map`), Gaussian-smoothed by ``sigma`` output pixels where the maps are
        kept, the new target. A player drifting through a sequence of maps uploads each once
        and reads none back. Needs a target set."""
        if self._target is None:
            raise InvalidArgumentError("next_time_map needs a target: set one with set_time_map(tmap, target)")
        new = self._check_tmap("target", target)
        check_float("sigma", sigma, 0.0, 1e4)
        self._tmap, self._target = self._target, new
        self._shift_tmap()
        self._smooth_maps(sigma, target_only=True)

    def _smooth_maps(self, sigma: float, target_only: bool) -> None:
        sigma = check_float("sigma", sigma, 0.0, 1e4) / self.time_step
        w = gaussian_weights(sigma)
        if len(w) == 1:
            return
        self._smooth(sigma, w, target_only)

    def set_tones(self, gain: np.ndarray, offset: np.ndarray | None = None) -> None:
        """Tone table: ``gain`` and ``offset`` ``(n, 3)`` (or ``(3,)`` for one tone), gain in [0, 63],
        offset in [-255, 255] (the range of the fixed-point tone)."""
        gain = np.atleast_2d(np.asarray(gain, np.float32))
        offset = np.zeros_like(gain) if offset is None else np.atleast_2d(np.asarray(offset, np.float32))
        if gain.ndim != 2 or gain.shape[1] != 3 or not 1 <= gain.shape[0] <= MAX_TONES:
            raise InvalidArgumentError(f"gain must have shape (n, 3) with 1 <= n <= {MAX_TONES}, not {gain.shape}")
        if offset.shape != gain.shape:
            raise InvalidArgumentError(f"offset must have shape {gain.shape}, not {offset.shape}")
        if not np.isfinite(gain).all() or gain.min() < 0 or gain.max() > MAX_GAIN:
            raise InvalidArgumentError(f"gain must be finite within [0, {MAX_GAIN:g}]")
        if not np.isfinite(offset).all() or np.abs(offset).max() > MAX_OFFSET:
            raise InvalidArgumentError(f"offset must be finite within [-{MAX_OFFSET:g}, {MAX_OFFSET:g}]")
        if self._source is not None:
            _, tone = unpack_source(self._source)
            if tone.size and tone.max() >= len(gain):
                raise InvalidArgumentError(
                    f"the source names tone {int(tone.max())} but only {len(gain)} tones are given"
                )
        self._tones = np.ascontiguousarray(np.concatenate([gain, offset], axis=1))
        self._upload_tones()

    @property
    def tones(self) -> np.ndarray:
        """The tone table ``(n, 6)``: gain rgb, offset rgb."""
        return self._tones.copy()

    # -- rendering -----------------------------------------------------------------------------
    def render(self, t: float, out: np.ndarray | None = None, *, fade: float = 0.0) -> np.ndarray:
        """The frame at global time ``t`` (frames), ``(H, W, 3)`` uint8, written into ``out`` when
        given; ``fade`` in [0, 1] moves the time map toward its target (:meth:`set_time_map`)."""
        if out is None:
            out = np.empty(self.out_shape, np.uint8)
        event = self.start(t, out, fade=fade)
        if event is not None:
            event.wait()
        return out

    def start(self, t: float, out: np.ndarray, *, fade: float = 0.0):
        """Start rendering the frame at ``t`` into ``out``; returns the event after which ``out``
        holds it (None: it already does). Maps, tones and sources may change at once."""
        if self._source is None:
            raise RuntimeError("set a source (set_source_map or set_source_grid) before render")
        check_out(out, self.out_shape)
        t = self._fold(float(t))
        self._last_t, self._last_fade = t, check_float("fade", fade, 0.0, 1.0)
        return self._launch(t, out)

    def draw(self, out: np.ndarray, t: float, *, fade: float = 0.0, wait: bool = True):
        """:meth:`start`, in the words of every engine (:class:`~dynatex.player.engines.Engine`):
        None once ``out`` holds the frame at ``t``, or with ``wait=False`` the event after which it does."""
        event = self.start(t, out, fade=fade)
        if wait and event is not None:
            event.wait()
            return None
        return event

    def render_reference(self, t: float, out: np.ndarray | None = None, *, fade: float = 0.0) -> np.ndarray:
        """The numpy reference of :meth:`render` (usable with either backend, for checks)."""
        h, w = self.out_shape[:2]
        pix, tone = source_indices(self._source, (h, w), self.frame_w, self._cell)
        tmap, target = self._maps()
        frames, weights = time_units(tmap, self._fold(float(t)), (h, w), self.time_step, target=target, fade=fade)
        rgb = gather_reference(
            self._stack, pix, tone, frames, weights, self._tones, wrap=self.wrap, interpolate=self.interpolate
        )
        return self.format.from_rgb(rgb, out)

    def _fold(self, t: float) -> float:
        """Fold the global time into one period so float32 keeps sub-frame precision forever."""
        if not math.isfinite(t):
            raise InvalidArgumentError(f"t must be finite, not {t!r}")
        if self.wrap == "loop":
            return math.fmod(t, self.n_frames) if abs(t) >= self.n_frames else t
        if self.wrap == "pingpong" and self.n_frames > 1:
            p = 2 * (self.n_frames - 1)
            return math.fmod(t, p) if abs(t) >= p else t
        # clamp (or a single frame): every time beyond the ends (maps stay within MAX_TIME) is
        # the same as one just beyond, and the integer time must not overflow
        return min(max(t, -2 * MAX_TIME), self.n_frames + 2 * MAX_TIME)

    def frame_traffic(self, t: float | None = None) -> dict[str, int]:
        """Bytes the frame at ``t`` (default: the last rendered) must move at least.

        ``output``: the frame written once (``H * W * 3``; straight into the caller's array
        where the device shares host memory, see :attr:`direct`; a copy out of a device
        buffer elsewhere is not counted, it is avoidable). ``stored``: the stored pixels the
        frame reads, each distinct (frame, pixel) once (``3`` bytes each), which is at most
        two per output pixel when interpolating and, for a small stored set (a few tiles
        over the frames that the time offsets reach), far fewer: such a set is re-read
        from cache rather than from memory, so the memory traffic is then close to the
        output alone. Source and time maps are not counted (a cell grid and a lattice of
        step 8 are tiny).
        """
        h, w = self.out_shape[:2]
        out = {"output": h * w * self.format.bytes, "stored": 0}
        if self._source is None:
            return out
        t = self._fold(self._last_t if t is None else float(t))
        tmap, target = self._maps()
        fp = self.frame_h * self.frame_w
        seen = np.zeros(self.n_frames * fp, bool)
        for r0 in range(0, h, 256):  # in blocks of rows: bounded memory
            rows = range(r0, min(r0 + 256, h))
            pix, _ = source_indices(self._source, (h, w), self.frame_w, self._cell, rows)
            i0, _ = time_units(tmap, t, (h, w), self.time_step, target=target, fade=self._last_fade, rows=rows)
            seen[wrap_index(i0, self.n_frames, self.wrap) * fp + pix] = True
            if self.interpolate:
                seen[wrap_index(i0 + 1, self.n_frames, self.wrap) * fp + pix] = True
        out["stored"] = 3 * int(np.count_nonzero(seen))
        return out

    @property
    def bytes_per_frame(self) -> int:
        """Bytes one render must move at least: the output written plus the distinct stored
        pixels read (:meth:`frame_traffic`, which says what is counted and what may be cached)."""
        return sum(self.frame_traffic().values())


class GatherReference(Gather):
    """The numpy reference engine: every frame is :meth:`Gather.render_reference`."""

    backend = "numpy"

    def _smooth(self, sigma: float, weights: np.ndarray, target_only: bool = False) -> None:
        if not target_only:
            self._tmap = gaussian_smooth(self._tmap, sigma)
        if self._target is not None:
            self._target = gaussian_smooth(self._target, sigma)

    def _launch(self, t: float, out: np.ndarray):
        self.render_reference(t, out, fade=self._last_fade)


class GatherOpenCL(Gather):
    """Kernel ``gather`` (``kernels/gather.cl``, or its verified x86 variant) on a device.

    ``ctx`` and ``queue`` are shared with the owner (the mode's player); both ``None`` use
    :func:`dynatex.player.opencl.context.get_context` (``device``) and a new queue. The engine owns
    its buffers: the frame stack, the source, the maps and the tones, uploaded when set;
    the maps are smoothed on the device and read back only when asked for.
    """

    backend = "opencl"

    def __init__(
        self,
        frames: np.ndarray,
        out_size: Sequence[int],
        *,
        ctx: Any = None,
        queue: Any = None,
        device: str | None = None,
        **options: Any,
    ) -> None:
        super().__init__(frames, out_size, **options)
        import pyopencl as cl

        from ..errors import OpenCLUnavailableError
        from ..opencl.context import variant_verified
        from ..opencl.programs import build_program
        from .base import FrameOut, Kernel, context_and_queue

        self.ctx, self.queue = context_and_queue(ctx, queue, device)
        mf = cl.mem_flags
        h, w = self.out_shape[:2]
        # the x86 variant only where the self-test verified it on this device
        wanted = self.time_step == 8 and self._wide_choice is not False
        self.wide = wanted and variant_verified(self.ctx.devices[0], "gather_wide")
        if wanted and self._wide_choice and not self.wide:
            raise OpenCLUnavailableError(
                f"wide=True: the gather_wide variant is not verified on {self.ctx.devices[0].name} "
                "(its self-test did not pass there); use wide=None or False"
            )
        # 16 floats of padding: the time step 8 kernel reads the maps 16 floats at a time
        self._d_tmap = cl.Buffer(self.ctx, mf.READ_WRITE, self._tmap.nbytes + 64)
        self._d_target = cl.Buffer(self.ctx, mf.READ_WRITE, self._tmap.nbytes + 64)
        self._d_tmp = cl.Buffer(self.ctx, mf.READ_WRITE, self._tmap.nbytes)
        self._d_tones = cl.Buffer(self.ctx, mf.READ_ONLY, MAX_TONES * TONE_STRIDE * 2)
        self._d_source: Any = None
        self._source_capacity = 0
        self._tmap_events: list[Any] = []
        self._weights: tuple[np.ndarray, Any] | None = None  # the smoothing taps and their buffer
        defines = {
            "FRAME_W": self.frame_w,
            "FRAME_PIXELS": self.frame_w * self.frame_h,
            "NFRAMES": self.n_frames,
            "GRID": self.grid,
            "WRAP": _WRAP_CODE[self.wrap],
            "CELL_H": (self.cell or (1, 1))[0],
            "CELL_W": (self.cell or (1, 1))[1],
            "INTERP": self.interpolate,
            "TSTEP": self.time_step,
            "RUN": RUN,
            "STACK_PAD": STACK_PAD,
            "TONE_STRIDE": TONE_STRIDE,
            "TONE_OB": TONE_OB,
        }
        defines.update(self.format.defines)
        if self.wide:
            files = ("pixels.cl", "gather.cl", "variants/gather_wide.cl")
            prog = build_program(self.ctx, files, {**defines, "STACK_SIGNED": True, "BANDS": BANDS})
        else:
            prog = build_program(self.ctx, ("pixels.cl", "gather.cl"), {**defines, "STACK_SIGNED": False})
        # STACK_PAD bytes on both sides: vector loads of a run may read a few bytes past the
        # frame stack's ends (lanes that a bytewise merge then drops). The wide variant
        # reads bytes value ^ 0x80: value - 128 as a signed byte, what its blend multiplies.
        padded = np.zeros(self._stack.nbytes + 2 * STACK_PAD, np.uint8)
        padded[STACK_PAD : STACK_PAD + self._stack.nbytes] = self._stack.reshape(-1)
        if self.wide:
            padded ^= 0x80
        self._d_stack = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=padded)
        self._k_gather = Kernel(prog, "gather_wide" if self.wide else "gather")
        self._k_gather.set(
            stack=self._d_stack,
            tmap=self._d_tmap,
            tones=self._d_tones,
            width=np.int32(w),
            height=np.int32(h),
            tmap_w=np.int32(self.tmap_shape[1]),
            tmap_h=np.int32(self.tmap_shape[0]),
            t0=np.float32(0),
            fade=np.float32(0),
        )
        self._out = FrameOut(self.ctx, self.queue, self._k_gather, "out", h * w * self.format.bytes)
        self._k_smooth_x = Kernel(prog, "smooth")
        self._k_smooth_y = Kernel(prog, "smooth")
        self.direct = self._out.direct
        # kernel gather: the wide kernel renders a run of 64 pixels on BANDS bands of 8 rows (a
        # band: rows 8k - 4 .. 8k + 3, one pair of map rows), the other RUN pixels of one row
        self._gsize = (-(-(w + 64) // 64), -(-(h + 4) // (8 * BANDS))) if self.wide else (-(-w // RUN), h)
        # one work-item per work-group there: left to itself PoCL may put the whole small
        # range into one work-group, which runs on one core
        self._lsize = (1, 1) if self.wide else None
        self._tsize = (_round_up(self.tmap_shape[1], 16), _round_up(self.tmap_shape[0], 4))
        self._upload_tmap()
        self._upload_tones()

    def _upload_source(self) -> None:
        import pyopencl as cl

        packed = self._source
        if self._d_source is None or self._source_capacity < packed.nbytes:
            self._d_source = cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY, max(packed.nbytes, 4))
            self._source_capacity = packed.nbytes
        cl.enqueue_copy(self.queue, self._d_source, packed, is_blocking=True)
        self._k_gather.set(source=self._d_source, grid_w=np.int32(packed.shape[1]))

    def _upload_tmap(self) -> None:
        import pyopencl as cl

        # not blocking: the queue runs in order, and the events (kept until the next upload:
        # dropping one would wait for the copy) hold the arrays until the copies are done
        # (set_time_map replaces the arrays rather than writing into them)
        self._tmap_events = [cl.enqueue_copy(self.queue, self._d_tmap, self._tmap, is_blocking=False)]
        if self._target is not None:
            self._tmap_events.append(cl.enqueue_copy(self.queue, self._d_target, self._target, is_blocking=False))
        self._set_tmap_args()

    def _set_tmap_args(self) -> None:
        # tmap1: the map the time map fades toward (the map itself when none is set)
        self._k_gather.set(tmap=self._d_tmap, tmap1=self._d_tmap if self._target is None else self._d_target)

    def _shift_tmap(self) -> None:
        import pyopencl as cl

        # the old target's buffer holds the new map: no copy on the device, one upload
        self._d_tmap, self._d_target = self._d_target, self._d_tmap
        self._tmap_events = [cl.enqueue_copy(self.queue, self._d_target, self._target, is_blocking=False)]
        self._set_tmap_args()

    def _upload_tones(self) -> None:
        import pyopencl as cl

        cl.enqueue_copy(self.queue, self._d_tones, _expand_tones(self._tones), is_blocking=True)

    def _maps(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The maps as the device holds them (smoothed there), read back."""
        import pyopencl as cl

        maps = []
        for host, device in ((self._tmap, self._d_tmap), (self._target, self._d_target)):
            if host is None:
                maps.append(None)
                continue
            m = np.empty_like(host)
            cl.enqueue_copy(self.queue, m, device, is_blocking=True)
            maps.append(m)
        return maps[0], maps[1]

    def _smooth(self, sigma: float, weights: np.ndarray, target_only: bool = False) -> None:
        import pyopencl as cl

        r = (len(weights) - 1) // 2
        if self._weights is None or not np.array_equal(self._weights[0], weights):  # uploaded once per sigma
            buf = cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=weights)
            self._weights = (weights, buf)
        d_w = self._weights[1]
        th, tw = self.tmap_shape
        dims = (np.int32(tw), np.int32(th), np.int32(r))
        maps = ([] if target_only else [self._d_tmap]) + ([self._d_target] if self._target is not None else [])
        for d_map in maps:
            passes = ((self._k_smooth_x, d_map, self._d_tmp, 0), (self._k_smooth_y, self._d_tmp, d_map, 1))
            for k, src, dst, along in passes:
                k.set(src=src, dst=dst, weights=d_w, w=dims[0], h=dims[1], radius=dims[2], along=np.int32(along))
                k.launch(self.queue, self._tsize)
        self.queue.finish()

    def _launch(self, t: float, out: np.ndarray):
        self._k_gather.set(t0=np.float32(t), fade=np.float32(self._last_fade))
        return self._out.launch(out, self._gsize, self._lsize, wait=False)

    def render_on_device(self, t: float, *, fade: float = 0.0) -> None:
        """Run the gather kernel alone into the device's own frame buffer and wait (no copy, no
        caller's array): the kernel-only time of the benchmarks."""
        if self._source is None:
            raise RuntimeError("set a source (set_source_map or set_source_grid) before render_on_device")
        self._k_gather.set(t0=np.float32(self._fold(float(t))), fade=np.float32(check_float("fade", fade, 0.0, 1.0)))
        self._out.launch_on_device(self._gsize, self._lsize).wait()

    def close(self) -> None:
        self.queue.finish()
        for name in ("_d_stack", "_d_tmap", "_d_target", "_d_tmp", "_d_tones", "_d_source"):
            buf = self.__dict__.pop(name, None)
            if buf is not None:
                buf.release()
        if self.__dict__.get("_weights") is not None:
            self._weights[1].release()
            self._weights = None


def open_gather(
    frames: np.ndarray,
    out_size: Sequence[int],
    *,
    backend: str = "opencl",
    ctx: Any = None,
    queue: Any = None,
    device: str | None = None,
    **options: Any,
) -> Gather:
    """A gather engine: :class:`GatherOpenCL` (``backend="opencl"``, on ``ctx``/``queue`` or
    ``device``) or :class:`GatherReference` (``"numpy"``); ``options`` as :class:`Gather`'s."""
    if backend not in BACKENDS:
        raise InvalidArgumentError(f"backend must be one of {BACKENDS}, not {backend!r}")
    if backend == "numpy":
        return GatherReference(frames, out_size, **options)
    return GatherOpenCL(frames, out_size, ctx=ctx, queue=queue, device=device, **options)


def _expand_tones(tones: np.ndarray) -> np.ndarray:
    """Device tone table (int16): per tone, the fixed-point gain of each byte of a 64-pixel run
    (192 values), then the offsets likewise, each 64-byte chunk in the word order of the
    wide kernel's byte interleave (:data:`_CHUNK_BYTES`), so a run loads its per-byte
    factors with vector loads. Bytes 0-2 come first: the per-pixel kernel reads those."""
    gain, offset = fixed_tones(tones)
    channel = _CHUNK_BYTES % 3
    out = np.zeros((len(tones), TONE_STRIDE), np.int16)
    out[:, :TONE_OB] = gain[:, channel]
    out[:, TONE_OB:] = offset[:, channel]
    return out


def _round_up(v: int, m: int) -> int:
    return -(-v // m) * m
