"""Mode ``tiles``: any size, endless output from triple toroid-shaped tiles.

The output is a lattice of tile cells. Each cell shows one tile of its class (seeded
random choice; the class comes from the caller's label map, default the main texture).
Each pixel plays its tile's loop at ``t + offset(x, t)``: per-cell offsets form a smooth
random field (neighbouring cells differ little, as the seed asks: "maximal change to
base time by neighbour patch"), spread over the pixels by a Gaussian of ``sigma`` output
pixels so time shifts gradually across cell borders, and drifting from one field to the
next over ``epoch`` frames so the output never repeats with the loop's period. Frames are
built by the shared :class:`~dynatex.player.engines.gather.Gather` (time interpolation between
neighbouring loop frames, per-tile colour tone).

Mixing: the edge between a cell of class ``a`` and one of class ``c`` belongs to class
``min(a, c)``. A cell whose edge belongs to another class ``c`` takes, along that edge,
the border tile ``(a, c, side)``: its own primary with a strip of ``c``'s primary
(ending at a minimum cut, then feathered), so both sides of the edge show ``c``'s
toroidal primary. Where strips of two sides overlap (corners) the pixel takes the tile
whose strip weighs more there, so the blend stays continuous. Cells that borrow a strip
show their class primary, which the border tiles carry beyond the strip. Colour tone is per class
(feathered pixels get a blended tone), so a ring keeps one tone wherever it appears.
Without mixing the source is a cell grid (no per-pixel map is read); with mixing a
per-pixel source map is built once per arrangement.

A Wang tile set (``construction="wang"`` in the analyzer) is arranged row by row so that
every shared edge has one colour on both sides (:meth:`TilesPlayer._wang_arrangement`);
a state whose arrangement breaks an edge is refused. A quilted set (the analyzer's default
for one texture) is the cells of one large torus: they are laid out in the torus's order,
shifted by a random number of cells per seed (:meth:`TilesPlayer._torus_arrangement`), so the
output is a window onto a seamless texture that repeats only with the torus's period. An output
larger than the torus would show that period; it takes the stochastic layout instead (option
``layout``, default ``auto``; :mod:`~dynatex.player.engines.stochastic`): random windows of the
torus on a triangle grid, each with its own time offset (the cell field sampled at its vertex),
blended so that the histogram holds. A frame costs 4-9x the torus's copy where the x86 gather
variant draws it (CPU time a frame at 1280x720 on the 2-core test machine: 7-8 ms on PoCL and 6 on
Intel's runtime, against 1-1.5 ms), a third to a half of the portable gather's (14-15 ms);
``layout="torus"`` keeps the copy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import (
    MAX_SIDE,
    Choice,
    Either,
    NpyFile,
    Numbers,
    Range,
    Size,
    Text,
    check_float,
    check_int,
    check_seed,
    check_size,
)
from ...errors import InvalidArgumentError
from ...params import Param
from ...tiledb import TilesModel
from ...tiledb.tiles import MAX_TONES
from ..base import Player, rng_from_state
from ..controls import Capabilities, Control
from ..engines import open_engine
from ..engines.gather import MAX_GAIN, MAX_TIME, gaussian_smooth, pack_source
from ..loop import render, repeats

TIME_STEP = 8  # output pixels per time-map sample
#: Largest ``sigma``, output pixels: smoothing costs time linear in it (0.46 s at 4K for 256 on a busy
#: 2-core PoCL, 7 s for 4096), and beyond a few tiles it flattens the offsets to their mean anyway.
MAX_SIGMA = 256.0
SPEED_RANGE = (-4.0, 4.0)
LABEL_PRESETS = ("halves", "stripes", "checker", "blobs")
LAYOUTS = ("auto", "torus", "stochastic")


def label_preset(name: str, shape: tuple[int, int], n_classes: int, *, seed: int = 0) -> np.ndarray:
    """A pixel label map ``(H, W)`` of class indices ``0 .. n_classes-1`` for quick mixing.

    ``halves``: vertical bands, one per class; ``stripes``: eight horizontal bands cycling
    the classes; ``checker``: a 4 x 4 board; ``blobs``: smooth random regions.

    Examples
    --------
    >>> label_preset("halves", (2, 4), 2).tolist()
    [[0, 0, 1, 1], [0, 0, 1, 1]]
    """
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    if name == "halves":
        return np.minimum(xx * n_classes // w, n_classes - 1).astype(np.int32)
    if name == "stripes":
        return ((yy * 8 // h) % n_classes).astype(np.int32)
    if name == "checker":
        return (((yy * 4 // h) + (xx * 4 // w)) % n_classes).astype(np.int32)
    if name == "blobs":
        rng = np.random.default_rng(seed)
        gh, gw = max(2, h // 64), max(2, w // 64)
        noise = gaussian_smooth(rng.random((gh, gw)).astype(np.float32), 1.0)
        cut = np.quantile(noise, np.linspace(0, 1, n_classes + 1)[1:-1])
        cells = np.searchsorted(cut, noise).astype(np.int32)
        return cells[np.minimum(yy * gh // h, gh - 1), np.minimum(xx * gw // w, gw - 1)]
    raise InvalidArgumentError(f"labels preset must be one of {LABEL_PRESETS}, not {name!r}")


def choose_layout(layout: str, size: Sequence[int], torus_shape: tuple[int, int] | None) -> str:
    """The layout a tiles player draws: ``"torus"`` (cells of the tile set edge to edge, as
    stored) or ``"stochastic"`` (:mod:`~dynatex.player.engines.stochastic`). ``"auto"`` takes
    the stochastic layout exactly when there is a torus and the output is larger than it in
    either direction; a set without a torus (ring or Wang tiles, mixtures) has only its cells.

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


def _fit_gain(hist: np.ndarray, target: float) -> float:
    """Gain ``g`` whose saturated output ``min(255, g v)`` has mean ``target`` over ``hist``.

    The seed fits mean colours by per-pixel multiplication; solving through the histogram
    keeps the fit exact when bright pixels saturate. Bisection on a monotone function.
    """
    v = np.arange(256, dtype=np.float64)
    n = hist.sum()
    if n == 0 or (hist[1:].sum() == 0):
        return 1.0
    lo, hi = 0.0, MAX_GAIN
    for _ in range(40):
        g = 0.5 * (lo + hi)
        mean = float((hist * np.minimum(255.0, np.rint(g * v))).sum() / n)
        lo, hi = (g, hi) if mean < target else (lo, g)
    return 0.5 * (lo + hi)


class TilesPlayer(Player):
    """Endless frames of any size from a texture's ``tiles`` group.

    Each class gets one tone gain per channel (per-pixel multiplication, as in the seed),
    solved so that the class's pixels *as arranged* (tile histograms weighted by their output
    area, with saturation at 255) have the target mean.

    Examples
    --------
    >>> with TilesPlayer("grass.h5", size=(2160, 3840), seed=2) as p:   # doctest: +SKIP
    ...     p.sigma = 48.0
    ...     frame = p.next_frame()                                       # (2160, 3840, 3)
    """

    mode = "tiles"
    method = "tiles"
    options = (
        Param("size", Size(MAX_SIDE), None, "Output size; any size.", optional=True, default_doc="the source clip's"),
        Param(
            "labels",
            Either(Choice(*LABEL_PRESETS), NpyFile(), metavar="PRESET|FILE.npy"),
            None,
            "Texture class of every tile cell: a (gh, gw) integer map (gh = ceil(H / th), gw = ceil(W / tw)), "
            "an (H, W) map sampled at the cell centres, or a preset (label_preset). Classes index class_names.",
            optional=True,
            default_doc="everything the main texture, class 0",
        ),
        Param(
            "layout",
            Choice(*LAYOUTS),
            "auto",
            "How a quilted torus covers the output: torus (its cells edge to edge, repeating with its period "
            "beyond its size; a copy, the fastest), stochastic (random windows of it blended on a triangle grid: "
            "no period at any size, 4-9x slower) or auto (stochastic exactly when the output is larger than "
            "the torus). Other tile sets have only their cells.",
            flag="--tile-layout",  # export's --layout names its file layout
        ),
    )
    capabilities = Capabilities(any_size=True, native_loop=True, inpaint=True)

    def _open(
        self,
        *,
        seed: int,
        size: Sequence[int] | None,
        labels: np.ndarray | None,
        layout: str,
        tone: Any = None,
    ) -> None:
        self._setup(self.texture.read(self.method), seed, size, labels, tone, layout)

    def _setup(self, model: TilesModel, seed: int, size, labels, tone, layout: str = "auto") -> None:
        self.model = model
        self.model_info = dict(model.info)
        k, length, th, tw, _ = model.tiles.shape
        self.loop_length, self.tile_size, self.n_tiles = length, (th, tw), k
        if size is None:
            src = self.texture.source
            size = (src.height, src.width)
        h, w = check_size("size", size, MAX_SIDE)
        self._shape = (h, w, self.format.bytes)
        self.grid_shape = (-(-h // th), -(-w // tw))
        self.ring = int(model.info.get("ring", max(2, min(th, tw) // 5)))
        self.seed = check_seed("seed", seed)  # label presets such as "blobs" draw from it
        self.labels = self._check_labels(labels)
        mixing = len(np.unique(self.labels)) > 1
        torus = None if model.torus is None else (model.torus[0] * th, model.torus[1] * tw)
        self.layout = choose_layout(layout, (h, w), torus)
        if self.layout == "stochastic":
            self.engine = open_engine(
                "stochastic",
                torus_frames(model.tiles, model.torus),
                (h, w),
                ctx=self.ctx,
                queue=self.queue,
                seed=self.seed,
                format=self.format,
            )
        else:
            # tiles stacked vertically in each stored frame: one tile's frame is contiguous, so a
            # cell's rows are read as one forward stream (hardware prefetch follows it)
            stack = np.ascontiguousarray(model.tiles.transpose(1, 0, 2, 3, 4).reshape(length, k * th, tw, 3))
            self.engine = open_engine(
                "gather",
                stack,
                (h, w),
                ctx=self.ctx,
                queue=self.queue,
                time_step=TIME_STEP,
                cell=None if mixing else (th, tw),
                format=self.format,
            )
        self.mixing = mixing
        c = model.n_classes
        #: quantization levels of a feathered pixel's tone share
        self._tone_levels = max(2, min(32, (MAX_TONES - 1 - c) // max(1, c * c)))
        self.engine.set_tones(*self._tone_tables(None))
        self._sigma = min(0.5 * min(th, tw), MAX_SIGMA)
        self._max_shift = min(length / 3.0, 16.0)
        self._epoch = 2 * length
        self._t = 0.0
        self._phase = 0
        self.tone_target(tone)  # checked here, fitted once the arrangement exists (_retone)
        self._tone = tone
        self.reseed(seed)
        self._warm()

    # -- arrangement ---------------------------------------------------------------------------
    @property
    def classes(self) -> list[str]:
        """Names of the tile classes (textures), index = label value."""
        return list(self.model.class_names)

    def _check_labels(self, labels) -> np.ndarray:
        gh, gw = self.grid_shape
        if labels is None:
            return np.zeros((gh, gw), np.int32)
        if isinstance(labels, str):
            labels = label_preset(labels, self._shape[:2], self.model.n_classes, seed=self.seed)
        lab = np.asarray(labels)
        if lab.dtype.kind not in "iub" or lab.ndim != 2:
            raise InvalidArgumentError(f"labels must be a 2-D integer map, not {lab.dtype} {lab.shape}")
        h, w = self._shape[:2]
        th, tw = self.tile_size
        if lab.shape == (h, w) and (h, w) != (gh, gw):
            cy = np.minimum(np.arange(gh) * th + th // 2, h - 1)
            cx = np.minimum(np.arange(gw) * tw + tw // 2, w - 1)
            lab = lab[cy][:, cx]
        if lab.shape != (gh, gw):
            raise InvalidArgumentError(
                f"labels must have shape {(gh, gw)} (tile cells) or {(h, w)} (pixels), not {lab.shape}"
            )
        n = self.model.n_classes
        if lab.size and (lab.min() < 0 or lab.max() >= n):
            bad = int(lab.max()) if lab.max() >= n else int(lab.min())
            raise InvalidArgumentError(
                f"labels name texture class {bad}, but the tile set has {n} class(es): "
                + ", ".join(f"{i}={c}" for i, c in enumerate(self.model.class_names))
            )
        return lab.astype(np.int32)

    def _arrange(self) -> None:
        """Choose a tile of its class for every cell (seeded) and build the gather's source."""
        m = self.model
        if m.wang:
            self._build_source(self._wang_arrangement())
            return
        if m.torus is not None:
            self._build_source(self._torus_arrangement(*(int(v) for v in self._rng.integers(0, m.torus))))
            return
        choice = np.empty(self.grid_shape, np.int64)
        for c in np.unique(self.labels):
            own = m.tiles_of(int(c))
            cells = self.labels == c
            choice[cells] = own[self._rng.integers(0, len(own), int(cells.sum()))]
        self._build_source(choice)

    def _wang_arrangement(self) -> np.ndarray:
        """A Wang set's cells row by row: random top colours for the first row and a random
        left colour per row; each cell draws its bottom colour, which (with its left and top)
        names its tile, whose right colour is then the next cell's left (right = (left + top +
        bottom) mod k, as :func:`dynatex.analyzer.tiles.wang_edges` builds the set)."""
        e = self.model.edges.astype(np.int64)
        k = int(e.max()) + 1
        lut = np.empty((k, k, k), np.int64)
        lut[e[:, 0], e[:, 2], e[:, 3]] = np.arange(len(e))
        gh, gw = self.grid_shape
        choice = np.empty((gh, gw), np.int64)
        top = self._rng.integers(0, k, gw)
        for i in range(gh):
            bottom = self._rng.integers(0, k, gw)
            right = (self._rng.integers(0, k) + np.cumsum(top + bottom)) % k
            left = np.r_[(right[0] - top[0] - bottom[0]) % k, right[:-1]]
            choice[i] = lut[left, top, bottom]
            top = bottom
        return choice

    def _torus_arrangement(self, dy: int, dx: int) -> np.ndarray:
        """A quilted set's cells in their torus order, the torus shifted by ``(dy, dx)`` cells:
        every shared edge is the torus continuing itself."""
        rows, cols = self.model.torus
        gh, gw = self.grid_shape
        return ((np.arange(gh)[:, None] + dy) % rows) * cols + (np.arange(gw)[None, :] + dx) % cols

    def _torus_mismatch(self, arrangement: np.ndarray) -> int:
        """Cells of ``arrangement`` out of their torus order (0 for the other constructions)."""
        if self.model.torus is None:
            return 0
        cols = self.model.torus[1]
        first = int(arrangement.flat[0])
        return int((arrangement != self._torus_arrangement(first // cols, first % cols)).sum())

    def _wang_mismatch(self, arrangement: np.ndarray) -> int:
        """Shared edges whose colours differ in ``arrangement`` (0 for a ring tile set)."""
        if not self.model.wang:
            return 0
        e = self.model.edges[arrangement]
        return int((e[:, :-1, 1] != e[:, 1:, 0]).sum() + (e[:-1, :, 3] != e[1:, :, 2]).sum())

    def _build_source(self, choice: np.ndarray) -> None:
        m = self.model
        th, tw = self.tile_size
        choice = np.array(choice, np.int64)
        self.arrangement = choice
        if self.layout == "stochastic":  # every cell of the torus shows alike; windows follow the arrangement
            self._class_map = None
            self._tile_pixels, self._partial_cells = np.full(self.n_tiles, float(th * tw)), []
            self.engine.set_windows(self.seed * self.n_tiles + int(choice.flat[0]))
            self._retone()
            return
        if not self.mixing:
            self._class_map = None
            h, w = self._shape[:2]
            vis_h = np.minimum(th, h - th * np.arange(choice.shape[0]))
            vis_w = np.minimum(tw, w - tw * np.arange(choice.shape[1]))
            area = np.outer(vis_h, vis_w)
            self._tile_pixels = np.bincount(choice.ravel(), weights=area.ravel(), minlength=self.n_tiles)
            # cells cut by the output's right or bottom edge show only their top-left part
            partial = (vis_h[:, None] < th) | (vis_w[None, :] < tw)
            self._partial_cells = [
                (int(choice[i, j]), int(vis_h[i]), int(vis_w[j])) for i, j in zip(*np.nonzero(partial))
            ]
            self.engine.set_source_grid(pack_source(choice * (th * tw), m.tile_class[choice]))
            self._retone()
            return
        h, w = self._shape[:2]
        yy, xx = np.arange(h), np.arange(w)
        ci, cj = yy // th, xx // tw
        ly, lx = yy - ci * th, xx - cj * tw
        lab = self.labels
        pad = np.pad(lab, 1, mode="edge")  # outside the output: own class
        neighbours = (pad[1:-1, :-2], pad[1:-1, 2:], pad[:-2, 1:-1], pad[2:, 1:-1])  # left right top bottom
        lut = np.full((m.n_classes, m.n_classes, 4), -1, np.int64)
        for kk in np.flatnonzero(m.border_side >= 0):
            lut[m.tile_class[kk], m.ring_class[kk], m.border_side[kk]] = kk
        # a cell lends its edge to the smaller class: both sides then show that class's primary
        side_tile = []
        for si, nb in enumerate(neighbours):
            edge = np.minimum(lab, nb)
            bt = np.where(edge != lab, lut[lab, edge, si], -1)
            if ((edge != lab) & (bt < 0)).any():
                raise InvalidArgumentError(
                    "the tile set has no border tile for some pair of neighbouring classes; "
                    "re-run the analysis with every texture of the label map mixed in"
                )
            side_tile.append(bt)
        touched = np.any([bt >= 0 for bt in side_tile], axis=0)
        for c in np.unique(lab[touched]):
            choice[touched & (lab == c)] = m.tiles_of(int(c))[0]  # the primary: border tiles share it
        self.arrangement = choice
        tile = choice[ci][:, cj]
        best_w = np.zeros((h, w), np.uint8)
        for bt in side_tile:
            btp = bt[ci][:, cj]
            wgt = np.where(btp >= 0, m.masks[np.maximum(btp, 0), ly[:, None], lx[None, :]], 0).astype(np.uint8)
            take = wgt > best_w
            tile = np.where(take, btp, tile)
            best_w = np.maximum(best_w, wgt)
        index = (tile * th + ly[:, None]) * tw + lx[None, :]
        weight = np.where(m.border_side[tile] >= 0, best_w, 255)
        self._class_map = np.where(weight >= 128, m.ring_class[tile], m.tile_class[tile]).astype(np.int32)
        self._weight, self._interior_class = weight, m.tile_class[tile].astype(np.int32)
        # tone per source class; feathered border-tile pixels get a blended tone (quantized share)
        tone = self._class_map.copy()
        feathered = (weight > 0) & (weight < 255) & (m.ring_class[tile] != m.tile_class[tile])
        if feathered.any():
            pair = m.tile_class[tile[feathered]] * m.n_classes + m.ring_class[tile[feathered]]
            q = np.rint(weight[feathered] / 255.0 * (self._tone_levels - 1)).astype(np.int64)
            tone[feathered] = m.n_classes + pair * self._tone_levels + q
        self._tile_pixels = np.bincount(tile.ravel(), minlength=self.n_tiles).astype(float)
        self._partial_cells = []
        self.engine.set_source_map(pack_source(index, tone))
        self._retone()

    def _retone(self) -> None:
        """Refit the tone to the current arrangement (the target stays)."""
        self.engine.set_tones(*self._tone_tables(self._tone))

    def source_class_map(self, *, strict: bool = False) -> np.ndarray:
        """``(H, W)`` class (texture) each output pixel mostly comes from: the true texture borders.

        With ``strict`` a border-tile pixel counts as the lending class only where it is
        that class alone (the minimum cut, before the feathering).
        """
        if self._class_map is not None:
            if strict:
                return np.where(self._weight == 255, self._class_map, self._interior_class)
            return self._class_map.copy()
        h, w = self._shape[:2]
        th, tw = self.tile_size
        return self.labels[np.arange(h) // th][:, np.arange(w) // tw]

    def set_labels(self, labels: np.ndarray | None) -> None:
        """Replace the label map (same rules as the constructor); the arrangement is redrawn."""
        lab = self._check_labels(labels)
        if (len(np.unique(lab)) > 1) != self.mixing:
            raise InvalidArgumentError("set_labels cannot switch between a single texture and a mix; open a new player")
        self.labels = lab
        self._arrange()

    # -- time offsets ------------------------------------------------------------------------------
    def _cell_field(self) -> np.ndarray:
        """Per-cell offsets in [0, 1]: smooth random field (neighbours differ little)."""
        gh, gw = self.grid_shape
        raw = gaussian_smooth(self._rng.random((gh, gw)).astype(np.float32), 1.5)
        lo, hi = float(raw.min()), float(raw.max())
        return (raw - lo) / (hi - lo) if hi > lo else np.full_like(raw, 0.5)

    def _pixel_field(self, cells: np.ndarray) -> np.ndarray:
        """Cell offsets spread on the time-map lattice (the engine smooths them by ``sigma``)."""
        th, tw = self.tile_size
        if self.layout == "stochastic":  # one offset per window: the cell field at its vertex
            vy, vx = self.engine.vertex_pixels
            return (cells[vy // th, vx // tw] * self._max_shift).astype(np.float32)
        mh, mw = self.engine.tmap_shape
        cy = np.minimum(((np.arange(mh) + 0.5) * TIME_STEP) // th, cells.shape[0] - 1).astype(int)
        cx = np.minimum(((np.arange(mw) + 0.5) * TIME_STEP) // tw, cells.shape[1] - 1).astype(int)
        return (cells[cy][:, cx] * self._max_shift).astype(np.float32)

    def _refresh_fields(self) -> None:
        """Both time fields uploaded once and smoothed where the engine keeps them (no read back)."""
        self.engine.set_time_map(self._pixel_field(self._cells_a), self._pixel_field(self._cells_b))
        self.engine.smooth_time_map(self._sigma)

    def _fade(self) -> float:
        """How far the time map has moved from field a toward field b (the device fades)."""
        return 0.0 if self._epoch == 0 else self._phase / self._epoch

    def _time_map(self) -> np.ndarray:
        """The time map of the next frame, as the device fades it (float32, same operations; the
        maps read back from the engine: for inspection, not for drawing)."""
        a, b = self.engine.time_map, self.engine.target_map
        f = np.float32(self._fade())
        return a + f * (b - a)

    def _advance_time(self) -> None:
        self._t = (self._t + self._speed) % self.loop_length
        if self._epoch:
            self._phase += 1
            if self._phase >= self._epoch:
                self._phase = 0
                self._cells_a = self._cells_b
                self._cells_b = self._cell_field()
                self.engine.next_time_map(self._pixel_field(self._cells_b), self._sigma)

    # -- controls ------------------------------------------------------------------------------------
    speed = Control(Range(float, *SPEED_RANGE), 1.0, "Loop frames per output frame.")
    sigma = Control(
        Range(float, 0.0, MAX_SIGMA),
        None,
        "Gaussian smoothing of the per-tile time offsets, output pixels (torus layout; in the stochastic "
        "layout each window keeps one offset and the blend spreads it).",
        default_doc=f"half a tile, at most {MAX_SIGMA:g}",
    )

    @sigma.setter
    def sigma(self, value: float) -> None:
        self._sigma = value
        self._refresh_fields()

    max_shift = Control(
        Range(float, 0.0, MAX_TIME),
        None,
        "Amplitude of the per-tile time offsets, frames (they wrap around the loop; more than a loop shears tiles).",
        default_doc="a third of the loop, at most 16",
    )

    @max_shift.setter
    def max_shift(self, value: float) -> None:
        self._max_shift = value
        self._refresh_fields()

    epoch = Control(
        Range(int, 0, 10**7),
        None,
        "Frames over which the offsets drift to a new random field (0: fixed offsets).",
        default_doc="twice the loop",
    )

    @epoch.setter
    def epoch(self, value: int) -> None:
        self._epoch = value
        self._phase = min(self._phase, max(0, self._epoch - 1))

    tone = Control(
        Either(
            Numbers(Range(float, 0.0, 255.0), 3, "R,G,B"),
            Range(int, 0, None),
            Text("TEXTURE|consensus"),
            metavar="TEXTURE|consensus|R,G,B",
        ),
        None,
        "Colour-tone target: a texture class's name or index (its mean RGB), consensus (the mean "
        "over all classes) or an RGB colour; None turns tone fitting off.",
        optional=True,
        default_doc="off",
    )

    @tone.setter
    def tone(self, value: Any) -> None:
        self.engine.set_tones(*self._tone_tables(value))
        self._tone = value

    def tone_target(self, value: Any) -> np.ndarray | None:
        """The RGB target ``value`` names (see ``tone``), or None when tone fitting is off."""
        m = self.model
        if value is None:
            return None
        class_means = self.class_mean_rgb()
        if isinstance(value, str):
            if value == "consensus":
                return class_means.mean(axis=0)
            if value not in m.class_names:
                raise InvalidArgumentError(
                    f"tone names texture {value!r}, which the tile set lacks "
                    f"(it has {', '.join(m.class_names)}, or 'consensus', or an RGB colour)"
                )
            return class_means[m.class_names.index(value)]
        if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            if not 0 <= value < m.n_classes:
                raise InvalidArgumentError(f"tone names texture class {value}, but the tile set has {m.n_classes}")
            return class_means[int(value)]
        rgb = np.asarray(value, dtype=float)
        if rgb.shape != (3,) or not np.isfinite(rgb).all() or rgb.min() < 0 or rgb.max() > 255:
            raise InvalidArgumentError(
                f"tone must be None, a texture name or index, 'consensus' or an RGB colour in 0..255, not {value!r}"
            )
        return rgb

    def _class_histograms(self) -> np.ndarray:
        """``(C, 3, 256)`` value histograms of each class as the current arrangement shows it:
        every tile's histogram (a few loop frames, cached) weighted by its output pixels; a
        cell cut by the output's edge counts with the histogram of the part it shows (a tile
        of a quilted torus is not alike all over: flames in one corner, night in another)."""
        m = self.model
        idx = np.unique(np.linspace(0, self.loop_length - 1, 32).round().astype(int))

        def histogram(k: int, rows: int, cols: int) -> np.ndarray:
            px = m.tiles[k, idx, :rows, :cols].reshape(-1, 3)
            return np.stack([np.bincount(px[:, ch], minlength=256) / len(px) for ch in range(3)])

        if getattr(self, "_tile_hist", None) is None:
            th, tw = self.tile_size
            self._tile_hist = np.stack([histogram(k, th, tw) for k in range(self.n_tiles)])
        counts = getattr(self, "_tile_pixels", None)
        partial = getattr(self, "_partial_cells", [])
        if counts is None:
            counts, partial = np.ones(self.n_tiles), []
        counts = np.array(counts, np.float64)
        extra = np.zeros((m.n_classes, 3, 256), np.float64)
        for k, rows, cols in partial:  # replace the full tile's share by the part shown
            counts[k] -= rows * cols
            extra[m.tile_class[k]] += rows * cols * histogram(k, rows, cols)
        counts = np.maximum(counts, 0.0)
        out = np.zeros((m.n_classes, 3, 256), np.float64)
        for c in range(m.n_classes):
            own = m.tile_class == c
            w = np.where(own, counts, 0.0)
            if w.sum() == 0 and not extra[c].any():
                w = own.astype(float)
            out[c] = np.tensordot(w, self._tile_hist, axes=1) + extra[c]
        return out

    def class_mean_rgb(self) -> np.ndarray:
        """``(C, 3)`` mean RGB of each class (over its own tiles)."""
        m = self.model
        return np.array([m.mean_rgb[m.tiles_of(c)].mean(axis=0) for c in range(m.n_classes)])

    def _tone_tables(self, value: Any) -> tuple[np.ndarray, np.ndarray]:
        """Per-class gains (tone index = class): the seed's per-pixel multiplication fitting
        a class's mean RGB to the target. Per class, not per tile, so the shared ring of a
        class gets one gain wherever it appears and stays seamless.

        A feathered border pixel already holds ``(1 - s) A + s R`` (interior class ``a``, ring
        class ``r``, share ``s``), so one gain must stand for ``(1 - s) g_a A + s g_r R``. The
        average of the two gains does not: where ``a`` is red and ``r`` blue, both gains are
        large in the channel the other class lacks, and the band turned magenta. The gain
        that carries the two classes' means there, ``((1 - s) g_a mu_a + s g_r mu_r) / ((1 - s)
        mu_a + s mu_r)``, puts the band's mean between the two toned means.
        """
        target = self.tone_target(value)
        c = self.model.n_classes
        gain = np.ones((c, 3), np.float64)
        mu = np.ones((c, 3), np.float64)
        if target is not None:
            hist = self._class_histograms()
            v = np.arange(256, dtype=np.float64)
            for ci in range(c):
                for ch in range(3):
                    gain[ci, ch] = _fit_gain(hist[ci, ch], float(target[ch]))
                    mu[ci, ch] = max(1.0, float((hist[ci, ch] * v).sum() / max(hist[ci, ch].sum(), 1e-12)))
        # blended entries for feathered border pixels: index c + (a * C + ring) * levels + q
        share = np.linspace(0.0, 1.0, self._tone_levels)[:, None]
        blend = [
            ((1 - share) * gain[a] * mu[a] + share * gain[r] * mu[r]) / ((1 - share) * mu[a] + share * mu[r])
            for a in range(c)
            for r in range(c)
        ]
        table = np.clip(np.concatenate([gain] + blend), 0.0, MAX_GAIN).astype(np.float32)
        return table, np.zeros_like(table)

    def _on_reseed(self) -> None:
        """Redraw the arrangement and the time offsets."""
        self._arrange()
        self._cells_a = self._cell_field()
        self._cells_b = self._cell_field()
        self._phase = 0
        self._refresh_fields()

    # -- synthesis ---------------------------------------------------------------------------------------
    def _warm(self) -> None:
        self.engine.draw(np.empty(self._shape, np.uint8), self._t, fade=self._fade())

    def _start(self, out: np.ndarray):
        event = self.engine.draw(out, self._t, fade=self._fade(), wait=False)
        self._advance_time()
        return event

    def inpaint(self, frame: np.ndarray, mask: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The caller's ``frame`` with its ``mask``-ed pixels replaced by the next synthesized frame.

        ``frame`` is ``(H, W, 3)`` uint8 of the player's size, ``mask`` ``(H, W)`` bool or
        0/1 integers (nonzero = fill). Advances the player by one frame.
        """
        frame = np.asarray(frame)
        if frame.dtype != np.uint8 or frame.shape != self._shape:
            raise InvalidArgumentError(f"frame must be uint8 with shape {self._shape}, not {frame.dtype} {frame.shape}")
        mask = np.asarray(mask)
        if mask.shape != self._shape[:2]:
            raise InvalidArgumentError(
                f"mask must have shape {self._shape[:2]} (the frame's height and width), not {mask.shape}"
            )
        if mask.dtype.kind not in "biu":
            raise InvalidArgumentError(f"mask must be boolean or integer, not {mask.dtype}")
        synth = self.next_frame()
        if out is None:
            out = frame.copy()
        elif out is not frame:
            np.copyto(out, frame)
        np.copyto(out, synth, where=(mask != 0)[..., None])
        return out

    def frame_traffic(self) -> dict[str, int]:
        """Bytes the last frame had to move at least: ``output`` (the frame written once) and
        ``stored`` (the distinct tile pixels it read; a few tiles over the frames the time
        offsets reach: usually cache-resident). See :meth:`Gather.frame_traffic`."""
        return self.engine.frame_traffic()

    @property
    def bytes_per_frame(self) -> int:
        """Bytes one frame must move at least: the output written plus the distinct tile data
        read (:meth:`frame_traffic`); the roofline figure of the benchmark divides this by
        the measured copy bandwidth."""
        return self.engine.bytes_per_frame

    # -- state --------------------------------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {
            "t": self._t,
            "phase": self._phase,
            "rng": self._rng.bit_generator.state,
            "seed": self.seed,
            "cells_a": self._cells_a.copy(),
            "cells_b": self._cells_b.copy(),
            "arrangement": self.arrangement.copy(),
            "labels": self.labels.copy(),
        }

    def _set_state(self, state: dict[str, Any]) -> None:
        rng = rng_from_state(state["rng"])
        labels = self._check_labels(state["labels"])
        cells = [np.asarray(state[k], np.float32) for k in ("cells_a", "cells_b")]
        arrangement = np.asarray(state["arrangement"], np.int64)
        t = check_float("t", state["t"], 0.0, float(self.loop_length))
        phase = check_int("phase", state["phase"], 0)
        max_shift = check_float("max_shift", state["max_shift"], 0.0, MAX_TIME)
        tone = state["tone"]
        self.tone_target(tone)  # validates it
        seed = check_seed("seed", state.get("seed", self.seed))
        if any(c.shape != self.grid_shape or not np.isfinite(c).all() for c in cells):
            raise InvalidArgumentError(f"state offsets must be finite with shape {self.grid_shape}")
        if arrangement.shape != self.grid_shape or arrangement.min() < 0 or arrangement.max() >= self.n_tiles:
            raise InvalidArgumentError("state arrangement does not fit this tile set")
        if not (self.model.tile_class[arrangement] == labels).all():
            raise InvalidArgumentError("state arrangement does not match its labels")
        mismatched = self._wang_mismatch(arrangement)
        if mismatched:
            raise InvalidArgumentError(f"state arrangement puts {mismatched} Wang edges of different colours together")
        mismatched = self._torus_mismatch(arrangement)
        if mismatched:
            raise InvalidArgumentError(
                f"state arrangement puts {mismatched} cells of the quilted torus out of their order"
            )
        # everything checked: now change the player
        self._rng, self.labels, self._t, self._phase = rng, labels, t, phase
        self._cells_a, self._cells_b = cells
        self.arrangement = arrangement
        self._max_shift = max_shift
        self.seed, self._tone = seed, tone
        self._build_source(arrangement)  # fits the tone to the arrangement too
        self._refresh_fields()

    # -- loop ---------------------------------------------------------------------------------------------
    def _native_loop(self, count: int | None, keep_pace: bool) -> tuple[np.ndarray, str, float]:
        """The tile loop itself (fixed time offsets, ``epoch = 0``), stepped at the speed that fits a
        whole number of loops into the frames (:func:`dynatex.player.loop.loop_frames`)."""
        length = self.loop_length
        n, loops = repeats(length, count, keep_pace)
        speed = length * loops / n
        hi = SPEED_RANGE[1]
        if not speed <= hi:
            raise InvalidArgumentError(
                f"{n} frames: a tiles loop of {length} frames needs at least {math.ceil(length / hi)} frames "
                f"(speed at most {hi:g})"
            )
        self.epoch = 0  # fixed time offsets: the output repeats with the tile loop
        self.speed = speed
        return render(self, n), f"tile loop of {length} frames at speed {speed:.4g}, {loops} time(s)", speed
