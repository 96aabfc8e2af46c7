"""The triple toroid-shaped tile set of a texture (the ``tiles`` group).

Every tile is an ``L x th x tw`` RGB block that loops seamlessly in t. Three constructions
join tiles in x and y. Ring: tiles of one class share one boundary ring (the class's
primary toroidal tile outside a minimum cut), so any arrangement of them is seamless; a
border tile is a class's primary with a strip of another class's primary along one side,
used where two classes meet. Wang (one class): every tile edge carries one of a few edge
colours, and tiles join where the colours of their shared edge match (``edges``). Quilted
(one class): the tiles are the cells of one large torus quilted from the clip
(``torus_rows`` x ``torus_cols`` cells, row-major), laid out in that order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from ._check import Checker
from ._describe import Described
from .source import SourceInfo

MAX_TILES = 4096
CONSTRUCTIONS = ("quilted", "ring", "wang")  # how tiles join in x and y (attribute ``construction``)
#: How far a stored mean colour may lie from the tiles' (the analyzer averages 16 sampled frames).
MEAN_RGB_TOLERANCE = 32.0
#: Entries of the player's tone table (a tone index is the top 8 bits of a packed source entry):
#: one tone per tile class, and for every pair of classes the blended tones of a feathered border.
MAX_TONES = 256
#: Most tile classes: their tones and at least two blend levels for every pair fit :data:`MAX_TONES`.
MAX_CLASSES = 10
STATIONARITY_WARN = 0.5  # below this a clip is not one texture all over (grass 0.74, sea 0.65)


@dataclass
class TilesModel(Described):
    """A set of triple toroid-shaped tiles.

    Attributes
    ----------
    tiles : (K, L, th, tw, 3) uint8
        Tile frames; frame ``L - 1`` is followed by frame 0 seamlessly.
    tile_class : (K,) int32
        Class (texture) of each tile's interior, ``0 .. C-1``.
    ring_class : (K,) int32
        Class of each tile's boundary ring; equal to ``tile_class`` for ordinary tiles,
        different for border tiles.
    masks : (K, th, tw) uint8
        Share of the ring source (the ring class's primary) in each pixel, 0..255: 255
        outside the cut, 0 inside, in between over a few pixels past the cut (feathering:
        ``info["ring_feather"]`` in ordinary tiles, ``info["feather"]`` in border tiles).
    border_side : (K,) int8
        For border tiles the side carrying the ring class's strip (0 left, 1 right, 2 top,
        3 bottom); -1 for ordinary tiles.
    seam_cost : (K,) float64
        Mean squared RGB error per pixel along the tile's ring-interior cut (0 for primaries).
    mean_rgb, mean_hsv : (K, 3) float64
        Colour statistics per tile: RGB on 0..255; HSV with hue in degrees, S and V in 0..1.
    class_names : list of str
        Name of each class (the main texture first, then the mixed-in textures).
    class_loop_start : (C,) int64
        First source frame of each class's loop.
    class_loop_cost : (C,) float64
        Frame-set loop cost of each class (RMS difference over the median frame step).
    class_toroid_cost : (C, 2) float64
        Mean cut error of the primary tile's horizontal and vertical toroidal cuts (zeros
        with the Wang construction, which has no primary).
    info : dict
        Scalars (tile size, loop length, period, band widths, ...) stored as attributes.
    edges : (K, 4) int8, optional
        Wang edge colours ``(left, right, top, bottom)`` of each tile, ``-1`` for tiles
        outside the Wang set (all of them with the ring construction; the default).
    """

    tiles: np.ndarray
    tile_class: np.ndarray
    ring_class: np.ndarray
    masks: np.ndarray
    border_side: np.ndarray
    seam_cost: np.ndarray
    mean_rgb: np.ndarray
    mean_hsv: np.ndarray
    class_names: list[str]
    class_loop_start: np.ndarray
    class_loop_cost: np.ndarray
    class_toroid_cost: np.ndarray
    info: dict = field(default_factory=dict)
    edges: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.edges is None:
            self.edges = np.full((len(self.tile_class), 4), -1, np.int8)

    @property
    def wang(self) -> bool:
        """Whether the tiles are a Wang set (join where edge colours match, ``edges``)."""
        return bool((np.asarray(self.edges) >= 0).any())

    @property
    def torus(self) -> tuple[int, int] | None:
        """``(rows, cols)`` of cells of a quilted torus (tile ``k`` is cell ``divmod(k, cols)``),
        or None for the other constructions."""
        if self.info.get("construction") != "quilted":
            return None
        return int(self.info["torus_rows"]), int(self.info["torus_cols"])

    @property
    def n_tiles(self) -> int:
        return int(self.tiles.shape[0])

    @property
    def loop_length(self) -> int:
        return int(self.tiles.shape[1])

    @property
    def tile_size(self) -> tuple[int, int]:
        return int(self.tiles.shape[2]), int(self.tiles.shape[3])

    @property
    def n_classes(self) -> int:
        return len(self.class_names)

    def tiles_of(self, cls: int, ring: int | None = None) -> np.ndarray:
        """Indices of the tiles with interior class ``cls`` and ring class ``ring`` (default ``cls``)."""
        ring = cls if ring is None else ring
        return np.flatnonzero((self.tile_class == cls) & (self.ring_class == ring))

    def describe(self) -> dict:
        """Facts as plain values: the ``info`` attributes, the tile set per class, its costs and colours,
        the Wang edges, and a ``warning`` when the clip was not one texture all over."""
        info = super().describe()
        pure = self.ring_class == self.tile_class
        info.update(
            n_tiles=self.n_tiles,
            tile_size=f"{self.tile_size[1]}x{self.tile_size[0]}",
            loop_length=self.loop_length,
            classes=list(self.class_names),
            tiles_per_class=[len(self.tiles_of(c)) for c in range(self.n_classes)],
            border_tiles=int((~pure).sum()),
            loop_start=self.class_loop_start.tolist(),
            loop_cost=[round(float(v), 4) for v in self.class_loop_cost],
            toroid_cut_cost=[[round(float(v), 2) for v in row] for row in self.class_toroid_cost],
            ring_seam_cost=[round(float(v), 2) for v in self.seam_cost],
            mean_rgb=[[round(float(v), 1) for v in row] for row in self.mean_rgb],
            tiles_mb=round(self.tiles.nbytes / 2**20, 2),
        )
        info.setdefault("construction", "wang" if self.wang else "ring")
        if self.wang:
            info["wang_edges_left_right_top_bottom"] = np.asarray(self.edges).tolist()
        warning = stationarity_warning(self.info)
        if warning:
            info["warning"] = warning
        return info

    def summary(self) -> str:
        """One line: the construction, tile size and count, the loop and the cut costs."""
        info = self.info
        th, tw = self.tile_size
        if self.torus is not None:
            return (
                f"quilted torus {info.get('period_w')}x{info.get('period_h')} of {self.n_tiles} cells of "
                f"{tw}x{th} (blocks {info.get('quilt_block')}), loop {self.loop_length} frames from "
                f"{self.class_loop_start.tolist()}, cut cost {info.get('quilt_seam_cost', 0):.4g}"
            )
        kind = (
            f"Wang set of {info.get('edge_colours')} edge colours"
            if self.wang
            else f"ring construction, toroidal cut cost {self.class_toroid_cost.mean():.4g}"
        )
        seams = self.seam_cost[self.seam_cost > 0]
        return (
            f"{self.n_tiles} tiles of {tw}x{th}, loop {self.loop_length} frames from "
            f"{self.class_loop_start.tolist()}, classes {', '.join(self.class_names)}, {kind}, ring seam cost "
            f"{seams.mean() if seams.size else 0:.4g}"
        )


def stationarity_warning(info: dict) -> str | None:
    """The warning for a tiles model whose clip is not spatially stationary (None otherwise).

    >>> stationarity_warning({"stationarity": 0.9}) is None
    True
    """
    figure = info.get("stationarity")
    if figure is None or float(figure) >= STATIONARITY_WARN:
        return None
    return (
        f"the clip is not one texture all over (stationarity {float(figure):.2f} < {STATIONARITY_WARN}: its "
        f"{info.get('stationarity_worst', 'statistics')} differs between parts of the frame, as with a single "
        f"object or a scene); tiles will repeat or misplace its structures"
    )


def write(group: h5py.Group, model: TilesModel) -> None:
    k, length, th, tw, _ = model.tiles.shape
    group.create_dataset("tiles", data=np.asarray(model.tiles, np.uint8), chunks=(1, 1, th, tw, 3), compression="lzf")
    group.create_dataset("tile_class", data=np.asarray(model.tile_class, np.int32))
    group.create_dataset("ring_class", data=np.asarray(model.ring_class, np.int32))
    group.create_dataset("masks", data=np.asarray(model.masks, np.uint8), compression="lzf")
    group.create_dataset("border_side", data=np.asarray(model.border_side, np.int8))
    group.create_dataset("edges", data=np.asarray(model.edges, np.int8))
    for name in ("seam_cost", "mean_rgb", "mean_hsv", "class_loop_cost", "class_toroid_cost"):
        group.create_dataset(name, data=np.asarray(getattr(model, name), np.float64))
    group.create_dataset("class_loop_start", data=np.asarray(model.class_loop_start, np.int64))
    group.create_dataset("class_names", data=np.array([n.encode("utf-8") for n in model.class_names], dtype="S64"))
    for key, value in model.info.items():
        group.attrs[key] = value
    group.attrs["n_tiles"] = k
    group.attrs["loop_length"] = length
    group.attrs["tile_h"] = th
    group.attrs["tile_w"] = tw


def read(group: h5py.Group, check: Checker, source: SourceInfo) -> TilesModel:
    k = check.attr(group, "n_tiles", int)
    length = check.attr(group, "loop_length", int)
    th = check.attr(group, "tile_h", int)
    tw = check.attr(group, "tile_w", int)
    if not 1 <= k <= MAX_TILES:
        check.fail(group.name + "@n_tiles", f"{k} tiles, outside 1..{MAX_TILES}")
    if not 2 <= length <= 1_000_000:
        check.fail(group.name + "@loop_length", f"loop length {length} outside 2..1000000")
    if not (4 <= th <= 8192 and 4 <= tw <= 8192):
        check.fail(group.name + "@tile_h", f"tile size {th}x{tw} outside 4..8192")
    ds = check.dataset
    names_raw = ds(group, "class_names", kind="S", shape=(range(1, MAX_CLASSES + 1),))
    c = len(names_raw)
    try:
        names = [bytes(n).decode("utf-8") for n in names_raw]
    except UnicodeDecodeError:
        check.fail(group.name + "/class_names", "names are not UTF-8")
    model = TilesModel(
        tiles=ds(group, "tiles", kind="u", shape=(k, length, th, tw, 3), read=False),
        tile_class=ds(group, "tile_class", kind="iu", shape=(k,)).astype(np.int32),
        ring_class=ds(group, "ring_class", kind="iu", shape=(k,)).astype(np.int32),
        masks=ds(group, "masks", kind="u", shape=(k, th, tw)),
        border_side=ds(group, "border_side", kind="i", shape=(k,)).astype(np.int8),
        seam_cost=ds(group, "seam_cost", kind="f", shape=(k,)),
        mean_rgb=ds(group, "mean_rgb", kind="f", shape=(k, 3)),
        mean_hsv=ds(group, "mean_hsv", kind="f", shape=(k, 3)),
        class_names=names,
        class_loop_start=ds(group, "class_loop_start", kind="iu", shape=(c,)),
        class_loop_cost=ds(group, "class_loop_cost", kind="f", shape=(c,)),
        class_toroid_cost=ds(group, "class_toroid_cost", kind="f", shape=(c, 2)),
        info=_info(group, check, th, tw),
        edges=_edges(group, check, k),
    )
    if model.tiles.dtype != np.uint8:
        check.fail(group.name + "/tiles", f"dtype {model.tiles.dtype} is not uint8")
    try:
        model.tiles = model.tiles[()]
    except MemoryError:  # out of memory is no defect of the file
        raise
    except Exception as exc:
        check.fail(group.name + "/tiles", f"data cannot be read, the file may be truncated or corrupt ({exc})")
    check.index_range(group.name + "/tile_class", model.tile_class, c)
    check.index_range(group.name + "/ring_class", model.ring_class, c)
    for cls in range(c):
        if model.tiles_of(cls).size == 0:
            check.fail(group.name + "/tile_class", f"class {cls} ({names[cls]!r}) has no tile of its own")
    border = model.ring_class != model.tile_class
    if (
        ((model.border_side < -1) | (model.border_side > 3)).any()
        or (model.border_side[border] < 0).any()
        or (model.border_side[~border] != -1).any()
    ):
        check.fail(group.name + "/border_side", "must be 0..3 for border tiles and -1 for the others")
    if (model.mean_rgb < 0).any() or (model.mean_rgb > 255).any():
        check.fail(group.name + "/mean_rgb", "values outside 0..255")
    actual = model.tiles.reshape(k, -1, 3).mean(axis=1, dtype=np.float64)
    worst = float(np.abs(model.mean_rgb - actual).max())
    if worst > MEAN_RGB_TOLERANCE:
        check.fail(
            group.name + "/mean_rgb",
            f"differs from the tiles' own mean colour by {worst:.0f} levels "
            f"(more than {MEAN_RGB_TOLERANCE:g}); the player fits colour tone to it",
        )
    _check_edges(group.name + "/edges", model, check)
    _check_torus(group.name, model, check)
    return model


def _check_torus(where: str, model: TilesModel, check: Checker) -> None:
    """A quilted set: one class, no border tiles, ``torus_rows * torus_cols`` tiles."""
    if model.info.get("construction") != "quilted":
        return
    for key in ("torus_rows", "torus_cols"):
        if key not in model.info:
            check.fail(where + "@" + key, "missing (construction 'quilted' needs the torus's cells)")
    try:
        rows, cols = int(model.info["torus_rows"]), int(model.info["torus_cols"])
    except (TypeError, ValueError):
        check.fail(where + "@torus_rows", "torus_rows and torus_cols must be integers")
    if rows < 1 or cols < 1 or rows * cols != model.n_tiles:
        check.fail(
            where + "@torus_rows",
            f"a {rows}x{cols} torus of cells needs {max(0, rows * cols)} tiles, not {model.n_tiles}",
        )
    if model.n_classes != 1 or (model.ring_class != model.tile_class).any():
        check.fail(where + "/tile_class", "a quilted set is one class without border tiles")


def _info(group: h5py.Group, check: Checker, th: int, tw: int) -> dict:
    """The attributes, with those the reader and the player use checked for type and range."""
    info = check.info(group)
    for name, lo, hi in (("ring", 0, min(th, tw)), ("edge_colours", 1, 8), ("strip_depth", 1, min(th, tw))):
        value = check.attr(group, name, int, None)
        if value is not None:
            if not lo <= value <= hi:
                check.fail(f"{group.name}@{name}", f"{value} outside {lo}..{hi}")
            info[name] = value
    if "construction" in info:
        info["construction"] = check.attr(group, "construction", str)
    return info


def _edges(group: h5py.Group, check: Checker, k: int) -> np.ndarray | None:
    """The ``edges`` dataset, range-checked before it is narrowed to int8 (absent: None)."""
    if "edges" not in group:
        return None
    e = check.dataset(group, "edges", kind="i", shape=(k, 4))
    if e.size and (e.min() < -1 or e.max() > 7):
        check.fail(group.name + "/edges", "values must be -1 or edge colours 0..7")
    return e.astype(np.int8)


def _check_edges(where: str, model: TilesModel, check: Checker) -> None:
    """Wang edges: whole rows of -1 or colours ``0 .. k-1``; one class; one tile per
    ``(left, top, bottom)`` with ``right = (left + top + bottom) mod k`` (the player fills
    cells row by row from the first three)."""
    e = np.asarray(model.edges)
    kind = model.info.get("construction", "ring")
    if kind not in CONSTRUCTIONS:
        check.fail(where.rsplit("/", 1)[0] + "@construction", f"must be one of {CONSTRUCTIONS}, not {kind!r}")
    if not model.wang:
        if (e != -1).any():
            check.fail(where, "values must be -1 or edge colours >= 0")
        if kind == "wang":
            check.fail(where, "construction is 'wang' but no tile has edge colours")
        return
    if kind != "wang":
        check.fail(where, f"tiles have edge colours but construction is {kind!r}")
    wang = (e >= 0).all(axis=1)
    if ((e >= 0).any(axis=1) & ~wang).any():
        check.fail(where, "a tile has colours on some edges and -1 on others")
    k = int(e[wang].max()) + 1
    if k > 8 or model.n_classes != 1 or not wang.all():
        check.fail(where, "a Wang set must be every tile of a single class, with at most 8 colours")
    attrs = where.rsplit("/", 1)[0]
    if int(model.info.get("edge_colours", k)) != k:
        check.fail(attrs + "@edge_colours", f"says {model.info['edge_colours']} but the edges use {k} colours")
    th, tw = model.tile_size
    depth = int(model.info.get("strip_depth", 1))
    if not 1 <= depth <= min(th, tw) // 2:
        check.fail(attrs + "@strip_depth", f"{depth} outside 1..{min(th, tw) // 2} for {th}x{tw} tiles")
    want = {(a, (a + b + c) % k, b, c) for a in range(k) for b in range(k) for c in range(k)}
    have = {tuple(int(v) for v in row) for row in e}
    if len(e) != len(want) or have != want:
        check.fail(
            where,
            f"a Wang set of {k} colours must hold one tile per (left, top, bottom) with right = "
            "(left + top + bottom) mod colours",
        )
