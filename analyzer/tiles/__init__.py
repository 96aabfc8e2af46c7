"""Triple toroid-shaped tiles (Richtr & Haindl, "Dynamic texture editing"): analysis.

Pipeline (each step is a public function, so it can be tested and reused):

1. :func:`tile_period` - tile size from the dominant spatial periodicity (mean power
   spectrum of a few frames; a multiple of the period inside ``[min_tile, max_tile]``,
   a default size when the texture has no clear period). Overridable.
2. :func:`find_loop` - the temporal loop: the start ``s`` and length ``L`` whose frame
   sets ``s .. s+o-1`` and ``s+L .. s+L+o-1`` are most alike (Schoedl's frame-distance
   matrix on thumbnails, longer loops mildly preferred).
3. :func:`transition_map` - per-pixel temporal transition: pixel ``p`` plays
   ``V[s+L+u]`` for ``u < tau(p)`` and ``V[s+u]`` afterwards, so its only jump sits at
   ``tau(p) in [0, o)`` where the two frame sets differ least there (the argmin of a
   spatially smoothed cost volume: a minimum-cost cut surface in time, not a crossfade).
   The loop ``G`` wraps seamlessly: ``G[L-1] = V[s+L-1]`` is followed by ``G[0] = V[s+L]``.
4. :func:`flow_magnitude` - mean optical-flow magnitude (OpenCV Farneback) over the loop.
5. :func:`toroidal_tile` - spatial toroidal cuts by dynamic programming on the overlap
   error summed over the loop frames: a block of ``(th + b) x (tw + b)`` is cut so that
   its right overlap continues its left edge (a closed vertical path, circular in y), then
   likewise vertically (a closed horizontal path, circular in x). The path may move by
   ``1 + round(flow_gain * flow)`` pixels per row (at most 3), so the band of freedom
   widens where the texture moves, and the overlap width ``b`` grows with the mean flow.
6. :func:`ring_join` - **construction of several mutually compatible tiles**: every tile
   of a class is the class's primary toroidal tile ``P`` outside a closed minimum cut and
   the loop at another place of the clip inside it (four DP cuts inside a ring of width
   ``r`` along the edges, costed by what the output holds across them, ``P`` fading into
   the other place over ``max(2, r // 2)`` pixels past the cut). All tiles of a class
   therefore carry exactly ``P``'s pixels along
   their edges; since ``P`` tiles seamlessly with itself, any two tiles of the class sit
   next to each other, in any arrangement, exactly as ``P`` sits next to ``P``. The price:
   ``P``'s ring shows at every tile, a lattice that calm textures make visible
   (:func:`dynatex.analyzer.metrics.lattice_correlation`).
6b. ``construction="wang"`` (one texture): **stochastic Wang tiles** (Cohen et al. 2003)
   instead of one shared ring. Each tile edge carries one of ``k`` colours; colour ``c`` of
   the vertical (horizontal) edges is one strip of the looped clip, ``2 d`` pixels across,
   taken at a typical place (spatial and temporal activity near the clip's median). A
   tile's ring is the inner halves of its four strips, split in the corners by small
   minimum cuts (:func:`wang_ring`, :func:`corner_cut`), joined to an interior from another
   place by the ring cuts of step 6. Two tiles whose shared edge has one colour show the two
   halves of one piece of clip there: seamless. :func:`wang_edges` lists the ``k**3`` tiles
   (one per left, top and bottom colour), so the player can fill cells row by row with a
   random fitting tile. Nothing repeats at every tile, but the cuts meet four different
   strips, which is harder to hide on textures with structures larger than the strips.
6c. ``construction="quilted"`` (one texture; the default without mixing): **a large
   quilted torus** instead of small tiles. The ring construction repeats its ring at every
   tile, and both ring and Wang sets repeat a handful of tiles, which a viewer sees as a
   grid (:func:`dynatex.analyzer.metrics.lattice_prominence`: 0.12-0.41 on real clips).
   :func:`quilted_torus` quilts blocks of the looped clip onto a torus of at least 512
   pixels (and twice the clip, up to 768) per side (image quilting of spatio-temporal blocks, like the
   quilt mode, with the overlap bands wrapping around so the torus tiles the plane), and
   :func:`torus_cells` cuts it into cells that the player lays out in torus order. Nothing repeats
   within the period; the cost is storage (the whole torus, so the loop is capped at 64
   frames by default). Blocks and overlaps follow the clip's feature scale
   (:func:`feature_scale`, the correlation length along its longest direction): small blocks
   with narrow overlaps for grain, large ones whose cuts have room around coarse features, and
   the coarse band of two blocks fades across the whole overlap, so blocks of different
   brightness leave no straight-edged fragments. Every cut (here and in steps 5-7) is smoothed and
   cross-faded (:func:`path_alpha`): a minimum-error path drawn pixel by pixel shows
   stair-step teeth.
7. Mixing: every extra texture gets a loop of the same length and its own tiles cut to the
   same size; a border tile ``(a, c, side)`` (:func:`side_join`) is class ``a``'s primary
   with a strip of class ``c``'s primary along one side, ending at a closed minimum cut and
   feathered beyond it (two different textures have no invisible cut). The cut's cost is
   what the output holds across it (the strip beside the first faded pixel, plus the
   edges a step of the path exposes), so it follows quiet paths of the strip texture; it
   may run deeper than the ring (as deep as leaves the fade short of the tile centre),
   since the strip continues ``c``'s cells at any depth. The player lends a
   cell of class ``a`` the strip of its neighbour's class ``c < a`` along their shared edge,
   so both sides of the edge show ``c``'s toroidal primary (see :mod:`dynatex.player.modes.tiles`).
8. Colour statistics per tile (mean RGB and HSV) for tone fitting.

One module per part: ``loop`` (steps 1-4), ``cuts`` (5), ``ring`` (6 and 7), ``wang`` (6b),
``quilted`` (6c), ``stats`` (8, and the clip's stationarity), ``sets`` (the ring and Wang analysis
step by step). :func:`learn_tiles`, here, checks the arguments and picks the construction.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...checks import check_int
from ...errors import InvalidArgumentError
from ...tiledb.tiles import (  # the stationarity warning lives with the model that describes it
    CONSTRUCTIONS,
    STATIONARITY_WARN,
    TilesModel,
    stationarity_warning,
)
from ..methods import check_params
from ..video import Clip, Progress
from .cuts import CUT_SMOOTH, CUT_SOFT, MAX_STEP, circular_cut, path_alpha, smooth_path, toroidal_tile
from .loop import (
    DEFAULT_MAX_TILE,
    DEFAULT_MIN_TILE,
    find_loop,
    flow_magnitude,
    looped_block,
    tile_period,
    transition_map,
)
from .quilted import (
    QUILT_MAX_LOOP,
    QUILT_MAX_PERIOD,
    QUILT_MAX_RUN,
    QUILT_MIN_PERIOD,
    QUILT_REUSE,
    learn_quilted,
    quilt_geometry,
    quilted_torus,
    torus_cells,
)
from .ring import SIDES, ring_join, side_join
from .sets import learn_set
from .stats import colour_stats, feature_scale, stationarity
from .wang import corner_cut, wang_edges, wang_ring

__all__ = [
    "CONSTRUCTIONS",
    "CUT_SMOOTH",
    "CUT_SOFT",
    "DEFAULT_MAX_TILE",
    "DEFAULT_MIN_TILE",
    "MAX_STEP",
    "QUILT_MAX_LOOP",
    "QUILT_MAX_PERIOD",
    "QUILT_MAX_RUN",
    "QUILT_MIN_PERIOD",
    "QUILT_REUSE",
    "SIDES",
    "STATIONARITY_WARN",
    "TilesModel",
    "circular_cut",
    "colour_stats",
    "corner_cut",
    "feature_scale",
    "find_loop",
    "flow_magnitude",
    "learn_tiles",
    "looped_block",
    "path_alpha",
    "quilt_geometry",
    "quilted_torus",
    "ring_join",
    "side_join",
    "smooth_path",
    "stationarity",
    "stationarity_warning",
    "tile_period",
    "toroidal_tile",
    "torus_cells",
    "transition_map",
    "wang_edges",
    "wang_ring",
]


def learn_tiles(
    clip: Clip | np.ndarray,
    *,
    tile: int | Sequence[int] | None = None,
    construction: str | None = None,
    n_tiles: int | None = None,
    edge_colours: int = 2,
    min_tile: int = DEFAULT_MIN_TILE,
    max_tile: int = DEFAULT_MAX_TILE,
    min_loop: int = 32,
    max_loop: int | None = None,
    transition: int = 8,
    overlap: int | None = None,
    ring: int | None = None,
    flow_gain: float = 0.5,
    mix: Sequence[Clip | np.ndarray] = (),
    names: Sequence[str] | None = None,
    feather: int | None = None,
    period: Sequence[int] | None = None,
    seed: int = 0,
    progress: Progress | None = None,
) -> TilesModel:
    """Cut triple toroid-shaped tiles from a clip (and, for mixing, from more clips).

    Parameters
    ----------
    clip : Clip or ndarray
        Frames ``(T, H, W, C)`` uint8 (grey clips are expanded to RGB).
    tile : int or (th, tw), optional
        Tile size; default from :func:`tile_period` within ``[min_tile, max_tile]``.
    construction : {"quilted", "ring", "wang"}, optional
        How tiles are made to join (module docstring). Default ``"quilted"`` for one
        texture, ``"ring"`` when mixing or when ``n_tiles`` or ``ring`` is given.
        ``"quilted"`` (one texture only): a torus of at
        least 512 pixels (and twice the clip, up to 768) per side, quilted from blocks of the
        looped clip (:func:`quilted_torus`) and cut into cells that the player lays out in
        their torus order (shifted at random), so no content repeats within the period;
        ``tile`` is then the quilt block size (default from :func:`quilt_geometry`) and
        ``max_loop`` defaults to 64 frames (the torus is stored whole). ``"ring"``: all tiles of a class
        share one boundary ring, so they join in any arrangement, and that ring repeats at
        every tile (a lattice shows on calm textures). ``"wang"`` (one texture only): every
        edge carries one of ``edge_colours`` strips and tiles join where their edge colours
        match, so nothing repeats at every tile; its cuts are harder to hide on textures
        with large structures (measured: benchmarks/quality_tiles.py).
    n_tiles : int, optional
        Tiles per texture with the ring construction (>= 1, default 4; the first is the
        primary toroidal tile). The Wang set has ``edge_colours ** 3`` tiles.
    edge_colours : int
        Strips per edge direction of the Wang construction (2..4).
    min_loop, max_loop : int
        Bounds of the loop length in frames (``max_loop`` defaults to the clip length).
    transition : int
        Frames ``o`` over which the per-pixel temporal transitions spread (>= 1).
    overlap : int, optional
        Width ``b`` of the toroidal overlap bands (default ``tile // 4`` plus twice the mean flow).
    ring : int, optional
        Width of the band in which the ring cuts run (default ``max(2, tile // 10)``; the
        ring is repeated by every tile of a class, so narrower means less periodic content).
    flow_gain : float
        Extra path freedom per pixel/frame of optical flow (0 disables the widening).
    mix : sequence of clips
        Further textures cut to the same tile size and loop length; border tiles join
        every ordered pair of textures.
    names : sequence of str, optional
        Class names (default ``"main"``, ``"mix1"``, ...).
    feather : int, optional
        Border tiles fade the other texture's strip into the interior over this many pixels
        past the cut (default ``max(ring, tile // 5)``; 0: a hard cut).
    period : (height, width), optional
        Period of the quilted torus (rounded up to whole cells; default from
        :func:`quilt_geometry`).
    seed : int
        Seed of the quilted construction's random picks.
    progress : callable(done, total), optional

    Returns
    -------
    TilesModel

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t, y, x = np.meshgrid(np.arange(40), np.arange(48), np.arange(64), indexing="ij")
    >>> g = 128 + 60 * np.sin(2 * np.pi * (t / 10 + x / 16)) + rng.normal(0, 3, t.shape)
    >>> frames = np.repeat(np.clip(g, 0, 255).astype(np.uint8)[..., None], 3, axis=3)
    >>> m = learn_tiles(frames, tile=16, n_tiles=2, min_loop=12, transition=4)
    >>> m.tiles.shape[0], m.tile_size, m.loop_length >= 12
    (2, (16, 16), True)
    """
    tile, construction, period, n_tiles, edge_colours, min_loop, max_loop, transition, ring, flow_gain = check_params(
        "tiles",
        tile=tile,
        construction=construction,
        period=period,
        n_tiles=n_tiles,
        edge_colours=edge_colours,
        min_loop=min_loop,
        max_loop=max_loop,
        transition=transition,
        ring=ring,
        flow_gain=flow_gain,
    )
    mix, names, min_tile, max_tile, overlap, feather, seed = check_params(
        "tiles", mix=mix, names=names, min_tile=min_tile, max_tile=max_tile, overlap=overlap, feather=feather, seed=seed
    )
    main = _frames("clip", clip)
    extra = [_frames(f"mix[{i}]", c) for i, c in enumerate(mix)]
    names = names if names is not None else ["main"] + [f"mix{i + 1}" for i in range(len(extra))]
    if len(names) != 1 + len(extra):
        raise InvalidArgumentError(f"names must name {1 + len(extra)} textures, not {len(names)}")
    if construction is None:  # ring options name the ring construction
        construction = "ring" if extra or n_tiles is not None or ring is not None else "quilted"
    _check_construction(construction, bool(extra), tile, n_tiles, period, edge_colours)
    if max_loop is not None:
        max_loop = check_int("max_loop", max_loop, min_loop)
    if transition >= min_loop:
        raise InvalidArgumentError(f"transition ({transition}) must be smaller than min_loop ({min_loop})")
    loop = {"min_loop": min_loop, "max_loop": max_loop, "transition": transition, "progress": progress}
    if construction == "quilted":
        return learn_quilted(main, names, block=tile, period=period, seed=seed, **loop)
    return learn_set(
        main,
        extra,
        names,
        construction=construction,
        tile=tile,
        n_tiles=4 if n_tiles is None else n_tiles,
        edge_colours=edge_colours,
        min_tile=min_tile,
        max_tile=check_int("max_tile", max_tile, min_tile),
        overlap=overlap,
        ring=ring,
        flow_gain=flow_gain,
        feather=feather,
        **loop,
    )


def _check_construction(construction: str, mixing: bool, tile, n_tiles: int | None, period, edge_colours: int) -> None:
    """The options that apply to ``construction`` only, refused with the others."""
    if construction in ("quilted", "wang") and mixing:
        raise InvalidArgumentError(
            f"construction {construction!r} cannot mix textures: border tiles need every class's shared ring "
            "(construction='ring')"
        )
    if construction == "quilted" and not (tile is None or isinstance(tile, int)):
        raise InvalidArgumentError(
            f"tile must be an integer (the quilt block size of construction 'quilted'), not {tile!r}"
        )
    if construction == "quilted" and n_tiles is not None:
        raise InvalidArgumentError(
            "n_tiles applies to construction 'ring' only; the quilted torus has as many cells as its period holds"
        )
    if construction != "quilted" and period is not None:
        raise InvalidArgumentError(f"period applies to construction 'quilted' only, not {construction!r}")
    if construction == "wang" and n_tiles is not None:
        raise InvalidArgumentError(
            f"n_tiles applies to construction 'ring' only; the Wang set has edge_colours ** 3 = {edge_colours**3} tiles"
        )


def _frames(name: str, clip: Clip | np.ndarray) -> np.ndarray:
    frames = clip.frames if isinstance(clip, Clip) else np.asarray(clip)
    if frames.ndim != 4 or frames.dtype != np.uint8 or frames.shape[3] not in (1, 3):
        raise InvalidArgumentError(
            f"{name} must be (T, H, W, C) uint8 frames with C 1 or 3, not {frames.dtype} {frames.shape}"
        )
    if frames.shape[3] == 1:
        frames = np.repeat(frames, 3, axis=3)
    return frames
