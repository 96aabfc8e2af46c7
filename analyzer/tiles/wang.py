"""Stochastic Wang tiles (Cohen et al. 2003; step 6b of :mod:`dynatex.analyzer.tiles`): edge
colours, corner cuts, and the Wang set of one texture.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...checks import check_int
from ...errors import InvalidArgumentError
from .loop import PRE_FRAMES, Texture, block_starts, even_sample, grey
from .ring import ring_feather, ring_tiles


# -- 6b. Wang edges ----------------------------------------------------------------------------
def wang_edges(colours: int) -> np.ndarray:
    """Edge colours ``(left, right, top, bottom)`` of a stochastic Wang tile set, ``(k**3, 4)`` int8.

    For every pair ``(left, top)`` there are ``k`` tiles, one per ``bottom`` colour, with
    ``right = (left + top + bottom) mod k``: a player that fills cells row by row, taking
    ``left`` and ``top`` from the neighbours already placed, always finds ``k`` tiles that fit
    and picks one at random (Cohen et al. 2003 use the same set of eight for two colours).

    Examples
    --------
    >>> e = wang_edges(2)
    >>> e.shape, sorted({(int(a), int(b)) for a, _, b, _ in e}) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    ((8, 4), True)
    """
    k = check_int("colours", colours, 1, 8)
    return np.array([(w, (w + n + s) % k, n, s) for w in range(k) for n in range(k) for s in range(k)], np.int8)


def corner_cut(hs: np.ndarray, vs: np.ndarray, band: int) -> np.ndarray:
    """Where a corner square takes the horizontal edge strip (True) rather than the vertical one.

    ``hs`` and ``vs`` are ``(n, d, d, 3)`` samples of the two strips, oriented so the tile's
    corner is at ``(0, 0)``, rows running away from the horizontal edge and columns away
    from the vertical one. A monotone staircase path from ``(0, 0)`` to ``(d-1, d-1)`` within
    ``band`` pixels of the diagonal minimises the summed squared difference of the strips
    along it; the horizontal strip keeps the side of the path along its own edge (path
    pixels included). Near the corner each strip then meets its own edge, up to ``band``
    pixels from the corner point, where the four tiles' strips meet.
    """
    d = hs.shape[1]
    cost = ((hs.astype(np.float32) - vs.astype(np.float32)) ** 2).sum(axis=(0, 3))
    ii, jj = np.mgrid[0:d, 0:d]
    cost = np.where(np.abs(ii - jj) <= band, cost, np.inf)
    acc = np.full((d, d), np.inf)
    acc[0, 0] = cost[0, 0]
    for i in range(d):
        for j in range(d):
            if i == j == 0:
                continue
            best = min(acc[i - 1, j] if i else np.inf, acc[i, j - 1] if j else np.inf)
            acc[i, j] = cost[i, j] + best
    first = np.full(d, d, np.int64)  # per row, the path's first column
    i, j = d - 1, d - 1
    while True:
        first[i] = min(first[i], j)
        if i == j == 0:
            break
        if i and (not j or acc[i - 1, j] <= acc[i, j - 1]):
            i -= 1
        else:
            j -= 1
    return jj >= first[:, None]


def wang_ring(
    hstrips: Sequence[np.ndarray],
    vstrips: Sequence[np.ndarray],
    edges: Sequence[int],
    depth: int,
    *,
    band: int | None = None,
) -> np.ndarray:
    """The boundary of a Wang tile: halves of its four edge strips, joined at the corners.

    ``hstrips[c]`` is a horizontal edge strip ``(L, 2 depth, tw, 3)``: its upper half is the
    bottom band of the tile above an edge of colour ``c``, its lower half the top band of the
    tile below. ``vstrips[c]`` ``(L, th, 2 depth, 3)`` likewise across vertical edges. Each
    strip is one piece of the (looped) clip, so two tiles that meet on an edge of one colour
    continue each other there exactly. ``edges`` is ``(left, right, top, bottom)``. Returns
    ``(L, th, tw, 3)``, defined within ``depth`` pixels of the edges (zero inside); corner
    squares are split by :func:`corner_cut`.
    """
    w, e, n, s = (int(v) for v in edges)
    length, th, _, _ = vstrips[0].shape
    tw = hstrips[0].shape[2]
    d = int(depth)
    if not 1 <= d <= min(th, tw) // 2:
        raise InvalidArgumentError(f"depth must be in 1..{min(th, tw) // 2} for a {th}x{tw} tile, not {d}")
    hc = np.zeros((length, th, tw, 3), np.uint8)
    vc = np.zeros_like(hc)
    hc[:, :d], hc[:, th - d :] = hstrips[n][:, d:], hstrips[s][:, :d]
    vc[:, :, :d], vc[:, :, tw - d :] = vstrips[w][:, :, d:], vstrips[e][:, :, :d]
    yy, xx = np.arange(th)[:, None], np.arange(tw)[None, :]
    in_h = (yy < d) | (yy >= th - d)
    in_v = (xx < d) | (xx >= tw - d)
    take_h = in_h & ~in_v
    u = even_sample(length, PRE_FRAMES)
    band = max(1, d // 3) if band is None else band
    for ys, xs in (
        (slice(0, d), slice(0, d)),
        (slice(0, d), slice(tw - d, tw)),
        (slice(th - d, th), slice(0, d)),
        (slice(th - d, th), slice(tw - d, tw)),
    ):
        fy, fx = ys.start > 0, xs.start > 0  # flip so the tile's corner is at (0, 0)
        h_sq, v_sq = hc[u][:, ys, xs], vc[u][:, ys, xs]
        if fy:
            h_sq, v_sq = h_sq[:, ::-1], v_sq[:, ::-1]
        if fx:
            h_sq, v_sq = h_sq[:, :, ::-1], v_sq[:, :, ::-1]
        m = corner_cut(h_sq, v_sq, band)
        m = m[::-1] if fy else m
        take_h[ys, xs] = m[:, ::-1] if fx else m
    return np.where(take_h[None, :, :, None], hc, vc)


def wang_set(tx: Texture, th: int, tw: int, r: int, colours: int, flow_gain: float, step, seed: int = 0):
    """The stochastic Wang set of one texture (:func:`wang_edges`).

    Edge strips: ``colours`` horizontal and ``colours`` vertical pieces of the looped clip at
    typical places apart from each other, each ``2 depth`` pixels across its edge (``depth``
    = the ring plus its feathering, as far as a ring cut and its fade reach). A tile's ring
    is the inner halves of its four strips (:func:`wang_ring`), joined to an interior from
    yet another place by the ring cuts (:func:`.ring.ring_join`).
    """
    d = r + ring_feather(r, th, tw) + 1
    f = tx.frames
    h, w = f.shape[1:3]
    act = tx.activity
    grad = np.zeros((h, w), np.float32)
    for i in even_sample(tx.length, 8) + tx.start:
        g = grey(f[i : i + 1])[0]
        grad[:, 1:] += np.diff(g, axis=1) ** 2
        grad[1:] += np.diff(g, axis=0) ** 2
    rng = np.random.default_rng(seed)

    typical: dict[tuple[int, int], list[tuple[int, int]]] = {}  # per strip shape, scored once

    def places(bh: int, bw: int) -> list[tuple[int, int]]:
        """Typical places first: spatial and temporal activity near the clip's median (a strip
        livelier or calmer than the rest would mark every edge it sits on), shuffled."""
        if (bh, bw) not in typical:
            ys, xs = block_starts(h, bh, max(2, bh // 4)), block_starts(w, bw, max(2, bw // 4))
            cand = [
                (
                    int(y),
                    int(x),
                    float(act[y : y + bh, x : x + bw].mean()) + 1e-6,
                    float(grad[y : y + bh, x : x + bw].mean()) + 1e-6,
                )
                for y in ys
                for x in xs
            ]
            ma, mg = np.median([c[2] for c in cand]), np.median([c[3] for c in cand])
            score = np.array([abs(np.log(c[2] / ma)) + abs(np.log(c[3] / mg)) for c in cand])
            best = np.argsort(score, kind="stable")[: max(2 * colours, len(cand) // 4)]
            typical[(bh, bw)] = [cand[i][:2] for i in best]
        best = typical[(bh, bw)]
        return [best[i] for i in rng.permutation(len(best))]

    taken: list[tuple[int, int, int, int]] = []

    def pick(bh: int, bw: int) -> tuple[int, int]:
        cands = places(bh, bw)
        for relax in (1.0, 0.5, 0.0):
            for y, x in cands:
                if all(
                    abs(y - ty) >= relax * (bh + th_) / 2 or abs(x - tx_) >= relax * (bw + tw_) / 2
                    for ty, tx_, th_, tw_ in taken
                ):
                    taken.append((y, x, bh, bw))
                    return y, x
        y, x = cands[0]
        taken.append((y, x, bh, bw))
        return y, x

    hstrips, vstrips = [], []
    for _ in range(colours):
        y, x = pick(2 * d, tw)
        hstrips.append(tx.block(y, x, 2 * d, tw))
        y, x = pick(th, 2 * d)
        vstrips.append(tx.block(y, x, th, 2 * d))
    edges = wang_edges(colours)
    rings = [wang_ring(hstrips, vstrips, e, d) for e in edges]
    tiles = ring_tiles(tx, rings, th, tw, r, flow_gain, step, taken=[(y, x) for y, x, _, _ in taken])
    return tiles, edges, d
