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
the torus's histogram. Weights are the barycentric coordinates raised to ``sharpness`` and
renormalised, and those under ``CUTOFF`` dropped, so each vertex shows its window alone
over most of its hexagon (a plain copy, as the gather draws) and windows meet in bands
along the hexagons' edges, narrow enough not to ghost. Windows span at most half the
torus, so a window never shows the torus's period.

What is fixed at open: the torus (device copy), the pattern of weights of one grid cell
(:func:`weight_table`), the window offsets (from the seed). Per frame the host computes
each vertex's stored frame and blend weight (a few hundred vertices at 4K) and uploads
them; the kernel (``kernels/stochastic.cl``) reads only those and the torus. The numpy
reference :func:`stochastic_reference` computes the same floats in the same order, so the
two backends agree exactly (tested on every verified device).

Examples
--------
>>> import numpy as np
>>> torus = np.random.default_rng(0).integers(0, 256, (4, 40, 48, 3), dtype=np.uint8)
>>> s = open_stochastic(torus, (100, 150), backend="numpy", seed=1)
>>> s.set_time_map(np.zeros(s.tmap_shape, np.float32))
>>> s.render(0.0).shape
(100, 150, 3)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..checks import check_float, check_out
from ..errors import InvalidArgumentError
from .base import BACKENDS
from .pixels import pixel_format

LAYOUTS = ("auto", "torus", "stochastic")
N_INVERSE = 4096  # entries of the inverse table per channel
G_RANGE = 6.0  # the inverse table covers Gaussian values in [-G_RANGE, G_RANGE)
ISCALE = N_INVERSE / (2 * G_RANGE)
SHARPNESS = 6.0  # exponent of the barycentric weights
CUTOFF = 0.02  # sharpened weights under this share are dropped (one window alone shows)
RUN = 16  # output pixels per work-item
ROWS = 256  # output rows per block of the numpy reference (bounded memory)


def choose_layout(layout: str, size: Sequence[int], torus_shape: tuple[int, int] | None) -> str:
    """The layout a tiles player draws: ``"torus"`` (cells of the tile set edge to edge, as
    stored) or ``"stochastic"`` (this module). ``"auto"`` takes the stochastic layout exactly
    when there is a torus and the output is larger than it in either direction; a set without
    a torus (ring or Wang tiles, mixtures) has only its cells.

    >>> choose_layout("auto", (1080, 1920), (576, 720)), choose_layout("auto", (500, 700), (576, 720))
    ('stochastic', 'torus')
    """
    if layout not in LAYOUTS:
        raise InvalidArgumentError(f"layout must be one of {LAYOUTS}, not {layout!r}")
    if torus_shape is None:
        if layout == "stochastic":
            raise InvalidArgumentError(
                "layout 'stochastic' needs a quilted tile set (one torus); this set is ring or Wang tiles "
                "(analyze with construction='quilted', the default for one texture)"
            )
        return "torus"
    if layout == "auto":
        h, w = size
        return "stochastic" if h > torus_shape[0] or w > torus_shape[1] else "torus"
    return layout


def torus_frames(tiles: np.ndarray, torus: tuple[int, int]) -> np.ndarray:
    """The quilted torus ``(L, rows * th, cols * tw, 3)`` from its cells ``tiles`` ``(k, L, th, tw, 3)``
    stored row by row (``k = rows * cols``)."""
    rows, cols = torus
    k, length, th, tw, _ = tiles.shape
    if k != rows * cols:
        raise InvalidArgumentError(f"a {rows}x{cols} torus needs {rows * cols} cells, not {k}")
    cells = tiles.reshape(rows, cols, length, th, tw, 3).transpose(2, 0, 3, 1, 4, 5)
    return np.ascontiguousarray(cells.reshape(length, rows * th, cols * tw, 3))


def triangle_cell(torus_shape: Sequence[int]) -> tuple[int, int]:
    """``(row height, width)`` of the triangle grid for a torus: the width half the torus's
    shorter side (even, so odd rows shift by whole pixels), equilateral triangles. A window
    then spans at most the torus (its hexagon is two cells wide)."""
    side = min(int(v) for v in torus_shape)
    w = max(4, (side // 2) // 2 * 2)
    return max(2, int(round(w * math.sqrt(3) / 2))), w


def weight_table(cell: Sequence[int], sharpness: float = SHARPNESS, cutoff: float = CUTOFF) -> np.ndarray:
    """``(ch, cw, 4)`` float32: for each pixel of one grid cell (``ch`` rows of a band, ``cw``
    columns), the blend weights of its triangle's three vertices and ``tri + 4 single``
    (module ``kernels/stochastic.cl`` says which triangle and vertex these name).

    Barycentric coordinates of the pixel centre, raised to ``sharpness``, renormalised, those
    under ``cutoff`` dropped and the rest renormalised again; a single one left is the window
    alone (weights (1, 0, 0) at its place), else Heitz and Neyret's variance-preserving
    weights ``s_i / sqrt(sum s_j^2)``.

    >>> t = weight_table((13, 16))
    >>> blend = t[..., 3] < 4
    >>> bool(np.allclose((t[blend][:, :3] ** 2).sum(-1), 1, atol=1e-6)), [int(v) for v in np.unique(t[..., 3] // 4)]
    (True, [0, 1, 2, 3])
    """
    ch, cw = (int(v) for v in cell)
    if ch < 1 or cw < 2 or cw % 2:
        raise InvalidArgumentError(f"cell must be (rows >= 1, even width >= 2), not {tuple(cell)}")
    y = (np.arange(ch) + 0.5)[:, None] * np.ones((1, cw))
    x = np.ones((ch, 1)) * (np.arange(cw) + 0.5)[None, :]
    half = cw / 2.0
    tri = np.where(2 * ch * x < cw * y, 0, np.where(2 * ch * (cw - x) < cw * y, 2, 1))
    # vertices (y, x) of each triangle, in the kernel's order
    verts = {
        0: ((0.0, 0.0), (ch, -half), (ch, half)),
        1: ((0.0, 0.0), (0.0, float(cw)), (ch, half)),
        2: ((0.0, float(cw)), (ch, half), (ch, cw + half)),
    }
    bary = np.zeros((ch, cw, 3))
    for t, ((y0, x0), (y1, x1), (y2, x2)) in verts.items():
        det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        b0 = ((y1 - y2) * (x - x2) + (x2 - x1) * (y - y2)) / det
        b1 = ((y2 - y0) * (x - x2) + (x0 - x2) * (y - y2)) / det
        sel = tri == t
        bary[sel] = np.stack([b0, b1, 1 - b0 - b1], -1)[sel]
    s = np.clip(bary, 0.0, 1.0) ** sharpness
    s /= s.sum(-1, keepdims=True)
    s = np.where(s < cutoff, 0.0, s)
    s /= s.sum(-1, keepdims=True)
    w = s / np.sqrt((s * s).sum(-1, keepdims=True))
    alone = (s > 0).sum(-1) == 1
    single = np.where(alone, np.argmax(s, -1) + 1, 0)
    w = np.where(alone[..., None], 0.0, w)
    return np.concatenate([w, (tri + 4 * single)[..., None]], -1).astype(np.float32)


def _normal_cdf(g: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.vectorize(math.erf)(np.asarray(g, np.float64) / math.sqrt(2.0)))


def gauss_tables(hist: np.ndarray, gain: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heitz and Neyret's tables from per-channel value histograms ``hist`` ``(3, 256)``:
    ``T`` ``(3, 256)`` float32, the standard-normal quantile of each value's mid-rank (a value
    drawn from the histogram comes out standard normal); ``inverse`` ``(3, N_INVERSE)``
    uint8, for Gaussian values on a lattice of ``1 / ISCALE`` from ``-G_RANGE``, the smallest
    value whose cumulative share reaches the value's normal probability (T's inverse, which
    gives the histogram back); ``tone`` ``(3, 256)`` uint8, a value times the tone ``gain``
    (per channel, default 1) rounded and saturated, which ``inverse`` also holds.

    >>> T, inv, tone = gauss_tables(np.ones((3, 256)))
    >>> bool(abs(T[0].mean()) < 1e-3), int(inv[0, (N_INVERSE // 2 + 1)]), int(tone[1, 200])
    (True, 128, 200)
    """
    hist = np.asarray(hist, np.float64)
    if hist.shape != (3, 256) or not np.isfinite(hist).all() or (hist < 0).any() or (hist.sum(1) <= 0).any():
        raise InvalidArgumentError(f"hist must be (3, 256) counts, some in every channel, not {hist.shape}")
    gain = np.ones(3) if gain is None else np.asarray(gain, np.float64)
    cdf = np.cumsum(hist, 1) / hist.sum(1, keepdims=True)
    mid = 0.5 * (cdf + np.concatenate([np.zeros((3, 1)), cdf[:, :-1]], 1))
    grid = np.linspace(-G_RANGE - 2, G_RANGE + 2, 8193)
    phi = _normal_cdf(grid)
    table = np.stack([np.interp(np.clip(m, 1e-9, 1 - 1e-9), phi, grid) for m in mid]).astype(np.float32)
    centres = (np.arange(N_INVERSE) + 0.5) / ISCALE - G_RANGE
    p = _normal_cdf(centres)
    v = np.stack([np.minimum(np.searchsorted(c, p), 255) for c in cdf])
    values = np.arange(256, dtype=np.float64)
    tone = np.stack([np.clip(np.rint(values * gain[ch]), 0, 255) for ch in range(3)]).astype(np.uint8)
    inverse = np.take_along_axis(tone, v, 1).astype(np.uint8)
    return table, inverse, tone


def vertex_grid(size: Sequence[int], cell: Sequence[int]) -> tuple[int, int]:
    """``(rows, columns)`` of the vertex table covering an output ``size`` with triangle ``cell``."""
    (h, w), (ch, cw) = size, cell
    return (h - 1) // ch + 2, (w - 1 + cw) // cw + 4


def vertex_pixels(size: Sequence[int], cell: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Output pixel ``(y, x)`` of every vertex (int, clipped into the output), ``(rows, columns)`` each."""
    (h, w), (ch, cw) = size, cell
    rows, cols = vertex_grid(size, cell)
    j = np.arange(rows)[:, None]
    x = (np.arange(cols)[None, :] - 2) * cw + (j & 1) * (cw // 2)
    y = j * ch + 0 * x
    return np.clip(y, 0, h - 1), np.clip(x, 0, w - 1)


def pixel_vertices(y: np.ndarray, x: np.ndarray, weights: np.ndarray, vcols: int):
    """For output pixels ``(y, x)`` (broadcast int arrays): their cell's weights ``(..., 4)``,
    the single window's place (1..3, 0: a blend) and the three vertex indices ``(3, ...)``
    into the flattened vertex table of ``vcols`` columns (the kernel's geometry)."""
    ch, cw = weights.shape[:2]
    j, r = y // ch, y % ch
    odd = j & 1
    xs = x + cw - odd * (cw // 2)
    i, c = xs // cw, xs % cw
    wt = weights[r, c]
    code = wt[..., 3].astype(np.int64)
    tri, single = code & 3, code >> 2
    top, bottom = j * vcols, (j + 1) * vcols
    vid = np.stack(
        [
            np.where(tri == 2, top + i + 2, top + i + 1),
            np.where(tri == 0, bottom + i + odd, np.where(tri == 1, top + i + 2, bottom + i + 1 + odd)),
            np.where(tri == 2, bottom + i + 2 + odd, bottom + i + 1 + odd),
        ]
    )
    return wt, single, vid


def window_labels(size: Sequence[int], cell: Sequence[int], weights: np.ndarray | None = None) -> np.ndarray:
    """``(H, W)`` int: the vertex (window) whose weight is largest at each output pixel, so
    the borders between labels run through the middle of the blend bands (for seam figures)."""
    h, w = (int(v) for v in size)
    ch, cw = (int(v) for v in cell)
    weights = weight_table((ch, cw)) if weights is None else weights
    y, x = np.arange(h)[:, None], np.arange(w)[None, :]
    wt, single, vid = pixel_vertices(y, x, weights, vertex_grid((h, w), (ch, cw))[1])
    k = np.where(single > 0, single - 1, np.argmax(wt[..., :3], -1))
    return np.take_along_axis(vid, k[None], 0)[0]


def vertex_table(
    offsets: np.ndarray, t: float, tmap: np.ndarray, target: np.ndarray | None, fade: float, n_frames: int
) -> np.ndarray:
    """``(rows, columns, 4)`` int32 of ``(oy, ox, frame, w)`` per vertex at time ``t``: the
    vertex's time ``t + m`` (``m`` its offset, faded from ``tmap`` toward ``target``), stored
    frame ``floor`` of it modulo ``n_frames`` and the weight of the next frame in 255ths."""
    m = np.asarray(tmap, np.float64)
    if target is not None:
        m = m + fade * (np.asarray(target, np.float64) - m)
    time = float(t) + m
    i0 = np.floor(time)
    w = np.rint((time - i0) * 255.0)
    i0 = np.where(w >= 255, i0 + 1, i0)
    w = np.where(w >= 255, 0, w)
    frame = np.mod(i0, n_frames)
    return np.concatenate([offsets, frame[..., None], w[..., None]], -1).astype(np.int32)


def stochastic_reference(
    torus: np.ndarray,
    weights: np.ndarray,
    vertices: np.ndarray,
    table: np.ndarray,
    inverse: np.ndarray,
    tone: np.ndarray,
    size: Sequence[int],
    *,
    rows: range | None = None,
) -> np.ndarray:
    """Reference of kernel ``stochastic``: ``(len(rows), W, 3)`` uint8 RGB of the output rows
    ``rows`` (default all) of an output ``size``, from the ``torus`` ``(L, TH, TW, 3)``, the
    cell's ``weights`` (:func:`weight_table`), the ``vertices`` (:func:`vertex_table`) and the
    tables (:func:`gauss_tables`). The same float32 operations in the same order as the kernel."""
    h, w = (int(v) for v in size)
    n, th, tw, _ = torus.shape
    vcols = vertices.shape[1]
    rows = range(h) if rows is None else rows
    flat = torus.reshape(n, th * tw, 3)
    vflat = vertices.reshape(-1, 4).astype(np.int64)
    y = np.arange(rows.start, rows.stop)[:, None] + np.zeros((1, w), np.int64)
    x = np.arange(w)[None, :] + np.zeros((len(rows), 1), np.int64)
    wt, single, vid = pixel_vertices(y, x, weights, vcols)
    inv255 = np.float32(1.0) / np.float32(255.0)
    ch3 = np.arange(3)

    def samples(v: np.ndarray, sel: np.ndarray):
        vv = vflat[v]
        p = ((y[sel] + vv[..., 0]) % th) * tw + (x[sel] + vv[..., 1]) % tw
        f = vv[..., 2]
        a = flat[f, p].astype(np.int64)
        b = flat[np.where(f + 1 == n, 0, f + 1), p].astype(np.int64)
        return a, b, vv[..., 3][..., None]

    out = np.empty((len(rows), w, 3), np.uint8)
    one = single > 0
    if one.any():
        v = np.choose(np.maximum(single - 1, 0), vid)[one]
        a, b, wb = samples(v, one)
        value = ((255 - wb) * a + wb * b + 127) // 255
        out[one] = tone[ch3, value]
    blend = ~one
    if blend.any():
        acc = np.zeros((int(blend.sum()), 3), np.float32)
        for k in range(3):
            a, b, wb = samples(vid[k][blend], blend)
            g = ((255 - wb).astype(np.float32) * table[ch3, a] + wb.astype(np.float32) * table[ch3, b]) * inv255
            acc = acc + wt[..., k][blend][:, None] * g
        q = np.clip(acc * np.float32(ISCALE) + np.float32(N_INVERSE // 2), 0, N_INVERSE - 1).astype(np.int64)
        out[blend] = inverse[ch3, q]
    return out


class Stochastic:
    """Frames of the stochastic layout of one ``torus`` ``(L, TH, TW, 3)`` uint8 at ``out_size``.

    The interface of both engines (:func:`open_stochastic` picks one), shaped like the gather
    engine's where a tiles player uses it: :attr:`tmap_shape` is the vertex grid and the time
    maps hold one offset per vertex (frames; :meth:`set_time_map` with a target fades between
    two, :meth:`render`'s ``fade``), :meth:`set_tones` takes the tone table of the gather
    (its first row's gains), :meth:`render` / :meth:`start` draw a frame at time ``t``.
    ``seed`` draws the window offsets; ``hist`` ``(3, 256)`` (default: the torus's own) builds the
    Gaussianizing tables.
    """

    backend = ""

    def __init__(
        self,
        torus: np.ndarray,
        out_size: Sequence[int],
        *,
        seed: int = 0,
        cell: Sequence[int] | None = None,
        sharpness: float = SHARPNESS,
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
        self.weights = weight_table(self.cell, check_float("sharpness", sharpness, 1.0, 64.0))
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

    def render_reference(self, t: float, out: np.ndarray | None = None, *, fade: float = 0.0) -> np.ndarray:
        """The numpy reference of :meth:`render` (either backend)."""
        if out is None:
            out = np.empty(self.out_shape, np.uint8)
        vertices = self.vertices(float(t), fade)
        h, w = self.out_shape[:2]
        for r0 in range(0, h, ROWS):
            rows = range(r0, min(r0 + ROWS, h))
            rgb = stochastic_reference(self.torus, self.weights, vertices, *self._tables, (h, w), rows=rows)
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

        from .engine import FrameOut, Kernel
        from .opencl import build_program, get_context

        self.ctx = get_context(device) if ctx is None else ctx
        self.queue = cl.CommandQueue(self.ctx) if queue is None else queue
        mf = cl.mem_flags
        h, w = self.out_shape[:2]
        th, tw = self.torus.shape[1:3]
        defines = {
            "TORUS_H": th,
            "TORUS_W": tw,
            "NFRAMES": self.n_frames,
            "CELL_H": self.cell[0],
            "CELL_W": self.cell[1],
            "VCOLS": self.tmap_shape[1],
            "N_INVERSE": N_INVERSE,
            "ISCALE": float(ISCALE),
            "RUN": RUN,
            **self.format.defines,
        }
        prog = build_program(self.ctx, "stochastic.cl", defines)
        self._d_torus = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=self.torus)
        self._d_weights = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=self.weights)
        self._vtab = np.zeros(self.tmap_shape + (4,), np.int32)
        self._d_vertices = cl.Buffer(self.ctx, mf.READ_ONLY, self._vtab.nbytes)
        self._d_table = cl.Buffer(self.ctx, mf.READ_ONLY, 3 * 256 * 4)
        self._d_inverse = cl.Buffer(self.ctx, mf.READ_ONLY, 3 * N_INVERSE)
        self._d_tone = cl.Buffer(self.ctx, mf.READ_ONLY, 3 * 256)
        self._k = Kernel(prog, "stochastic")
        self._k.set(
            torus=self._d_torus,
            weights=self._d_weights,
            vertices=self._d_vertices,
            table=self._d_table,
            inverse=self._d_inverse,
            tone=self._d_tone,
            width=np.int32(w),
            height=np.int32(h),
        )
        self._out = FrameOut(self.ctx, self.queue, self._k, "out", h * w * self.format.bytes)
        self.direct = self._out.direct
        self._gsize = (-(-w // RUN), h)
        self._upload_tables()

    def _upload_tables(self) -> None:
        if not hasattr(self, "_k"):
            return  # the base class sets its first tables before the kernel exists
        import pyopencl as cl

        table, inverse, tone = self._tables
        for buf, host in ((self._d_table, table), (self._d_inverse, inverse), (self._d_tone, tone)):
            cl.enqueue_copy(self.queue, buf, np.ascontiguousarray(host), is_blocking=True)

    def _launch(self, vertices: np.ndarray, out: np.ndarray):
        import pyopencl as cl

        self._vtab = np.ascontiguousarray(vertices, np.int32)
        cl.enqueue_copy(self.queue, self._d_vertices, self._vtab, is_blocking=True)
        return self._out.launch(out, self._gsize, None, wait=False)

    def render_on_device(self, t: float, *, fade: float = 0.0) -> None:
        """The kernel alone into the device's own frame buffer, waited for (the benchmarks' kernel time)."""
        import pyopencl as cl

        self._vtab = np.ascontiguousarray(self.vertices(float(t), fade), np.int32)
        cl.enqueue_copy(self.queue, self._d_vertices, self._vtab, is_blocking=True)
        self._out.launch_on_device(self._gsize, None).wait()

    def close(self) -> None:
        self.queue.finish()
        for name in ("_d_torus", "_d_weights", "_d_vertices", "_d_table", "_d_inverse", "_d_tone"):
            buf = self.__dict__.pop(name, None)
            if buf is not None:
                buf.release()


def open_stochastic(
    torus: np.ndarray,
    out_size: Sequence[int],
    *,
    backend: str = "opencl",
    ctx: Any = None,
    queue: Any = None,
    device: str | None = None,
    **options: Any,
) -> Stochastic:
    """A stochastic-layout engine: :class:`StochasticOpenCL` (``backend="opencl"``) or
    :class:`StochasticReference` (``"numpy"``); ``options`` as :class:`Stochastic`'s."""
    if backend not in BACKENDS:
        raise InvalidArgumentError(f"backend must be one of {BACKENDS}, not {backend!r}")
    if backend == "numpy":
        return StochasticReference(torus, out_size, **options)
    return StochasticOpenCL(torus, out_size, ctx=ctx, queue=queue, device=device, **options)
