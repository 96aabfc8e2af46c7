"""The ring and Wang constructions of :func:`~dynatex.analyzer.tiles.learn_tiles`: a few tiles per
texture that join in any arrangement (ring) or where their edge colours match (Wang), and, when
textures are mixed, the border tiles between every ordered pair of them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ...errors import InvalidArgumentError
from ...framestats import median_step
from ...tiledb.tiles import TilesModel
from ..video import Progress
from .cuts import primary_tile
from .loop import STEP_PAIRS, Texture, find_loop, flow_magnitude, progress_steps, tile_period, transition_map
from .ring import SIDES, ring_feather, ring_tiles, side_join
from .stats import colour_stats, stationarity_info
from .wang import wang_set


def learn_set(
    main: np.ndarray,
    extra: Sequence[np.ndarray],
    names: list[str],
    *,
    construction: str,
    tile,
    n_tiles: int,
    edge_colours: int,
    min_tile: int,
    max_tile: int,
    min_loop: int,
    max_loop: int | None,
    transition: int,
    overlap: int | None,
    ring: int | None,
    flow_gain: float,
    feather: int | None,
    progress: Progress | None,
) -> TilesModel:
    """The ring or Wang set of ``main`` (and the ring sets and border tiles of the ``extra`` textures)."""
    n_own = edge_colours**3 if construction == "wang" else n_tiles
    total = 6 + n_own + len(extra) * (3 + n_tiles) + (len(extra) + 1) * len(extra)
    step = progress_steps(progress, total)

    (th, tw), period, strength = _tile_size(main, extra, tile, min_tile, max_tile)
    step()
    textures = _textures(main, extra, min_loop, max_loop, transition, step)
    mean_flow = float(np.mean([tx.flow.mean() for tx in textures]))
    widths = _widths(main, extra, th, tw, mean_flow, overlap, ring, feather)
    r = widths["ring"]

    tiles: list[tuple[np.ndarray, int, int, np.ndarray, float, int]] = []  # tile, class, ring class, mask, cost, side
    edges = None  # ring sets: the model's default, no colours
    wang_info = {}
    if construction == "wang":
        step()
        wang, edges, strip_depth = wang_set(textures[0], th, tw, r, edge_colours, flow_gain, step)
        tiles += [(tile_k, 0, 0, mask, cost, -1) for tile_k, mask, cost in wang]
        wang_info = {"edge_colours": edge_colours, "strip_depth": strip_depth}
    else:
        tiles += _ring_sets(textures, th, tw, widths, n_tiles, flow_gain, step)
    step()
    tiles += _border_tiles(textures, widths, flow_gain, step)
    stats = [colour_stats(t[0]) for t in tiles]
    step()
    model = TilesModel(
        tiles=np.stack([t[0] for t in tiles]),
        tile_class=np.array([t[1] for t in tiles], np.int32),
        ring_class=np.array([t[2] for t in tiles], np.int32),
        masks=np.stack([t[3] for t in tiles]),
        border_side=np.array([t[5] for t in tiles], np.int8),
        seam_cost=np.array([t[4] for t in tiles]),
        mean_rgb=np.array([s[0] for s in stats]),
        mean_hsv=np.array([s[1] for s in stats]),
        class_names=names,
        class_loop_start=np.array([tx.start for tx in textures], np.int64),
        class_loop_cost=np.array([tx.cost for tx in textures]),
        class_toroid_cost=np.array([tx.toroid_cost for tx in textures]),
        edges=edges,
        info={
            "construction": construction,
            **wang_info,
            **stationarity_info(main),
            "tile_h": th,
            "tile_w": tw,
            "loop_length": textures[0].length,
            "transition": transition,
            **widths,
            "ring_feather": ring_feather(r, th, tw),
            "period_y": period[0],
            "period_x": period[1],
            "periodicity": strength,
            "mean_flow": mean_flow,
            "flow_gain": float(flow_gain),
            "source_frames": main.shape[0],
            "n_classes": len(textures),
            "median_frame_step": median_step(main, pairs=STEP_PAIRS),
        },
    )
    step(total)
    return model


def _tile_size(
    main: np.ndarray, extra: Sequence[np.ndarray], tile, min_tile: int, max_tile: int
) -> tuple[tuple[int, int], tuple[float, float], float]:
    """The tile size (``tile``: an int or (th, tw) checked by
    :func:`~dynatex.analyzer.tiles.learn_tiles`, or None), the spatial period it comes from and
    that period's strength (0 when given)."""
    if tile is None:
        (th, tw), period, strength = tile_period(main, min_tile=min_tile, max_tile=max_tile)
        for f in extra:
            th, tw = min(th, f.shape[1] // 2), min(tw, f.shape[2] // 2)
    else:
        th, tw = (tile, tile) if isinstance(tile, int) else tile
        period, strength = (0.0, 0.0), 0.0  # not measured: the caller chose the size
    for label, f in [("clip", main)] + [(f"mix[{i}]", e) for i, e in enumerate(extra)]:
        if th + 2 > f.shape[1] or tw + 2 > f.shape[2]:
            raise InvalidArgumentError(
                f"tile {th}x{tw} (plus a 2-pixel overlap) is larger than the {label} frame {f.shape[1]}x{f.shape[2]}"
            )
    return (th, tw), period, strength


def _textures(
    main: np.ndarray,
    extra: Sequence[np.ndarray],
    min_loop: int,
    max_loop: int | None,
    transition: int,
    step: Callable[[], None],
) -> list[Texture]:
    """The loop of the main texture, then a loop of the same length in every extra texture."""
    start, length, loop_cost = find_loop(main, min_loop=min_loop, max_loop=max_loop, transition=transition)
    step()
    tau = transition_map(main, start, length, transition)
    textures = [Texture(main, start, length, loop_cost, tau, flow_magnitude(main, start, length))]
    step()
    for f in extra:
        s, _, c = find_loop(f, min_loop=min_loop, transition=transition, length=length)
        textures.append(
            Texture(f, s, length, c, transition_map(f, s, length, transition), flow_magnitude(f, s, length))
        )
        step()
    return textures


def _widths(
    main: np.ndarray,
    extra: Sequence[np.ndarray],
    th: int,
    tw: int,
    mean_flow: float,
    overlap: int | None,
    ring: int | None,
    feather: int | None,
) -> dict[str, int]:
    """Overlap bands of the toroidal cuts, ring width, border feathering and depth (the model's info)."""
    h, w = main.shape[1:3]
    b = max(2, min(th, tw) // 4) + int(round(2 * mean_flow)) if overlap is None else overlap
    by = max(2, min(b, h - th, *(f.shape[1] - th for f in extra)))
    bx = max(2, min(b, w - tw, *(f.shape[2] - tw for f in extra)))
    # a narrow ring: every tile of a class repeats it, so it is the only periodic content
    r = max(2, min(th, tw) // 10) if ring is None else ring
    if r > min(th, tw) // 2 - 1:
        raise InvalidArgumentError(f"ring must be at most {min(th, tw) // 2 - 1} for a {th}x{tw} tile, not {r}")
    fe = max(r, min(th, tw) // 5) if feather is None else feather
    fe = min(fe, min(th, tw) // 2 - 1 - r)
    # border cuts may run deeper than the ring (the strip is the other class's toroidal
    # primary, which continues its own cells at any depth), as deep as leaves the fade
    # short of the tile centre: more room for a quiet path (grass|water, 250 frames, at
    # the cut: 1.6x the inside seams with depth 2 * ring, 1.15x with this)
    depth = max(r, min(th, tw) // 2 - 1 - fe)
    return {"overlap_y": by, "overlap_x": bx, "ring": r, "feather": fe, "border_depth": depth}


def _ring_sets(
    textures: list[Texture], th: int, tw: int, widths: dict[str, int], n_tiles: int, flow_gain: float, step
) -> list[tuple]:
    """Every class's primary toroidal tile, then ``n_tiles - 1`` tiles sharing its ring."""
    by, bx, r = widths["overlap_y"], widths["overlap_x"], widths["ring"]
    for tx in textures:
        tx.primary, tx.primary_pos, tx.toroid_cost = primary_tile(tx, th, tw, by, bx, flow_gain)
        step()
    out = []
    for ci, tx in enumerate(textures):
        out.append((tx.primary, ci, ci, np.full((th, tw), 255, np.uint8), 0.0, -1))
        rings = [tx.primary] * (n_tiles - 1)
        for tile_k, mask, cost in ring_tiles(tx, rings, th, tw, r, flow_gain, step, taken=[tx.primary_pos]):
            out.append((tile_k, ci, ci, mask, cost, -1))
    return out


def _border_tiles(textures: list[Texture], widths: dict[str, int], flow_gain: float, step) -> list[tuple]:
    """For every ordered pair of classes ``(a, c)`` and side: a strip of ``c``'s primary along ``a``'s."""
    out = []
    for a, ta in enumerate(textures):
        for c, tc in enumerate(textures):
            if a == c:
                continue
            for si, side in enumerate(SIDES):
                tile_k, mask, cost = side_join(
                    tc.primary, ta.primary, widths["border_depth"], side, feather=widths["feather"], flow_gain=flow_gain
                )
                out.append((tile_k, a, c, mask, cost, si))
            step()
    return out
