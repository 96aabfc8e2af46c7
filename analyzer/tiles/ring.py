"""Ring joins (steps 6 and 7 of :mod:`dynatex.analyzer.tiles`): tiles that carry their class's
primary ring around another place of the clip, and border tiles between two classes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...errors import InvalidArgumentError
from .cuts import CUT_SOFT, circular_cut, dp_path, path_alpha, path_steps
from .loop import PRE_FRAMES, SAMPLE_FRAMES, Texture, block_starts, even_sample, lively_first


# -- 6. ring join -------------------------------------------------------------------------------
def ring_join(
    ring_tile: np.ndarray,
    inner: np.ndarray,
    ring: int,
    *,
    flow: np.ndarray | None = None,
    flow_gain: float = 0.5,
    feather: int = 0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """``ring_tile`` outside a closed minimum cut, ``inner`` inside it.

    The cut runs inside a ring of width ``ring`` along the four edges: four DP paths (left,
    right, top, bottom), each keeping at least the outermost pixel from ``ring_tile``.
    With ``feather > 0`` (border tiles between two different textures, which no cut can
    join invisibly) ``ring_tile`` fades out linearly over ``feather`` pixels inside the cut,
    else the two cross-fade over :data:`CUT_SOFT` pixels across it; the paths are smoothed
    first (:func:`path_alpha`), so the cut shows no stair-step teeth.
    Returns ``(tile, weight, cost)``; ``weight`` (uint8, 0..255) is the share of
    ``ring_tile`` in each pixel (255 outside the cut), ``cost`` the mean squared RGB error
    per frame along the four paths.
    """
    length, th, tw = ring_tile.shape[:3]
    if not 2 <= ring <= min(th, tw) // 2 - 1:
        raise InvalidArgumentError(f"ring must be in 2..{min(th, tw) // 2 - 1} for a {th}x{tw} tile, not {ring}")
    u = even_sample(length, SAMPLE_FRAMES)
    flow = np.zeros((th, tw), np.float32) if flow is None else flow
    alpha = np.zeros((th, tw))
    costs = []
    # per side (oriented as the left edge): path over rows, column c in 1..ring = first pixel
    # past the cut; the cost is what the output holds across the cut (see _cut_cost)
    for side in ("left", "right", "top", "bottom"):
        e, move = _cut_cost(
            _orient(ring_tile, side, tile_axes=(1, 2)), _orient(inner, side, tile_axes=(1, 2)), ring, feather, u
        )
        fl = _orient(flow, side, tile_axes=(0, 1))
        path, cost = dp_path(e, path_steps(fl[:, :ring].mean(axis=1), flow_gain), None, move)
        costs.append(cost)
        soft = (
            path_alpha(path, fl.shape[1], fade=feather + 1.0, start=1.0, lo=1)
            if feather > 0
            else path_alpha(path, fl.shape[1], fade=CUT_SOFT, lo=1)
        )
        alpha = np.maximum(alpha, _unorient(soft, side, tile_axes=(0, 1)))
    weight = np.rint(255 * alpha).astype(np.uint8)
    a = (weight.astype(np.float32) / 255)[None, :, :, None]
    tile = np.rint(a * ring_tile + (1 - a) * inner.astype(np.float32)).astype(np.uint8)
    return np.ascontiguousarray(tile), weight, float(np.mean(costs))


SIDES = ("left", "right", "top", "bottom")


def _orient(a: np.ndarray, side: str, *, tile_axes: tuple[int, int]) -> np.ndarray:
    """View ``a`` so that ``side`` becomes the left edge (an involution for left/right, and
    its own inverse applied with :func:`_unorient`)."""
    y, x = tile_axes
    if side == "left":
        return a
    if side == "right":
        return np.flip(a, axis=x)
    if side == "top":
        return np.swapaxes(a, y, x)
    return np.flip(np.swapaxes(a, y, x), axis=x)


def _unorient(a: np.ndarray, side: str, *, tile_axes: tuple[int, int]) -> np.ndarray:
    y, x = tile_axes
    if side in ("left", "right", "top"):
        return _orient(a, side, tile_axes=tile_axes)
    return np.swapaxes(np.flip(a, axis=x), y, x)


def _cut_cost(rt: np.ndarray, it: np.ndarray, ring: int, feather: int, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Costs of a cut near the left edge of ``rt`` (outside) / ``it`` (inside), both ``(L, n, m, 3)``.

    The cost of a cut is what the output holds across it: ``rt``'s last pixel beside the
    first pixel past the cut, ``a1 * rt + (1 - a1) * it`` (``a1`` the first step of the
    fade, 0 for a hard cut). With a soft fade that is mostly ``rt``'s own gradient, so the
    cut seeks its quiet paths (and, through the ``1 - a1`` share, places where the two
    agree). Returns ``e (n, ring + 1)`` (column ``c`` = first pixel past the cut; column 0
    is forbidden) and ``move (n,)``: the cost per column a path step between rows
    ``i - 1`` and ``i`` exposes (``rt`` beside the faded pixels across those rows).
    """
    n = rt.shape[1]
    a1 = 1.0 - 1.0 / float(feather + 1) if feather > 0 else 0.0
    k = ring + 1
    rs = rt[u, :, :k].astype(np.float32)
    blend = a1 * rs + (1.0 - a1) * it[u, :, :k].astype(np.float32)
    d = rs[:, :, : k - 1] - blend[:, :, 1:k]  # rt at x-1 | blend at x, x = 1..ring
    e = np.empty((n, k), np.float32)
    e[:, 0] = 1e30
    e[:, 1:] = (d * d).sum(axis=(0, 3)) / len(u)
    dv = rs[:, :, 1:k] - np.roll(blend[:, :, 1:k], 1, axis=1)
    move = ((dv * dv).sum(axis=(0, 3)) / len(u)).mean(axis=1)
    return e, move


def side_join(
    ring_tile: np.ndarray,
    inner: np.ndarray,
    ring: int,
    side: str,
    *,
    feather: int = 0,
    flow: np.ndarray | None = None,
    flow_gain: float = 0.5,
) -> tuple[np.ndarray, np.ndarray, float]:
    """A border tile: ``inner`` with a strip of ``ring_tile`` along one ``side``.

    The strip ends at a closed minimum-error DP path (circular along the edge, so strips of
    cells stacked along that edge join) at depth ``1 .. ring``; beyond it ``ring_tile``
    fades out linearly over ``feather`` pixels, measured across the edge only (so the fade
    is periodic along the edge too). Returns ``(tile, weight, cost)``: ``weight`` (uint8)
    is the share of ``ring_tile`` per pixel, 255 in the strip.
    """
    if side not in SIDES:
        raise InvalidArgumentError(f"side must be one of {SIDES}, not {side!r}")
    ax = (1, 2)
    rt = _orient(ring_tile, side, tile_axes=ax)
    it = _orient(inner, side, tile_axes=ax)
    length, n, m = rt.shape[:3]
    if not 2 <= ring <= m // 2 - 1:
        raise InvalidArgumentError(f"ring must be in 2..{m // 2 - 1} for this tile, not {ring}")
    e, move = _cut_cost(rt, it, ring, feather, even_sample(length, SAMPLE_FRAMES))
    fl = np.zeros((n, m), np.float32) if flow is None else _orient(flow, side, tile_axes=(0, 1))
    path, cost = circular_cut(e, path_steps(fl[:, :ring].mean(axis=1), flow_gain), move)
    alpha = path_alpha(path, m, fade=feather + 1.0, start=1.0, lo=1, circular=True)
    weight = np.rint(255 * alpha).astype(np.uint8)
    a = (weight.astype(np.float32) / 255)[None, :, :, None]
    tile = np.rint(a * rt + (1 - a) * it.astype(np.float32)).astype(np.uint8)
    tile = np.ascontiguousarray(_unorient(tile, side, tile_axes=ax))
    weight = np.ascontiguousarray(_unorient(weight, side, tile_axes=(0, 1)))
    return tile, weight, cost


def ring_tiles(
    tx: Texture,
    rings: Sequence[np.ndarray],
    th: int,
    tw: int,
    r: int,
    flow_gain: float,
    step,
    taken: Sequence[tuple[int, int]] = (),
):
    """One tile per ring tile in ``rings``: the ring joined to the loop at another place.

    Places are ranked by how well their edges match the ring (lively places first), and
    kept apart from each other and from ``taken`` where the clip allows. The ring cuts are
    feathered over ``max(2, r // 2)`` pixels inside the cut: a hard cut between two places
    of a smooth texture (sea waves) showed ~10x the interior gradient.
    """
    if not rings:
        return []
    rf = ring_feather(r, th, tw)
    f = tx.frames
    h, w = f.shape[1:3]
    u = even_sample(tx.length, PRE_FRAMES)
    ringmask = np.ones((th, tw), bool)
    ringmask[r : th - r, r : tw - r] = False
    stride_y, stride_x = max(4, th // 4), max(4, tw // 4)
    places = [(int(y), int(x)) for y in block_starts(h, th, stride_y) for x in block_starts(w, tw, stride_x)]
    act = tx.activity
    chosen: list[tuple[int, int]] = list(taken)
    out = []
    ranked, ranked_for = [], None
    for ring_tile in rings:
        if ring_tile is not ranked_for:
            ring_u = ring_tile[u].astype(np.float32)
            ranked = []
            for y, x in places:
                d = tx.block(y, x, th, tw, u).astype(np.float32) - ring_u
                e = (d * d).sum(axis=(0, 3))
                ranked.append((float(e[ringmask].mean()), y, x, float(act[y : y + th, x : x + tw].mean())))
            ranked, ranked_for = lively_first(ranked), ring_tile
        pick = None
        for relax in (0.5, 0.0, -1.0):  # places apart from the chosen ones, then allow overlap
            pick = next(
                (
                    (y, x)
                    for _, y, x, _ in ranked
                    if (y, x) not in chosen
                    and not any(abs(y - cy) < th * relax and abs(x - cx) < tw * relax for cy, cx in chosen)
                ),
                None,
            )
            if pick is not None:
                break
        if pick is None:  # a tiny clip: every place is taken
            pick = ranked[len(out) % len(ranked)][1:3]
        y, x = pick
        tile, mask, cost = ring_join(
            ring_tile, tx.block(y, x, th, tw), r, flow=tx.flow[y : y + th, x : x + tw], flow_gain=flow_gain, feather=rf
        )
        out.append((tile, mask, cost))
        chosen.append((y, x))
        step()
    return out


def ring_feather(r: int, th: int, tw: int) -> int:
    return min(max(2, r // 2), min(th, tw) // 2 - 1 - r)
