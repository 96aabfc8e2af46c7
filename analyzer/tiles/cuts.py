"""Minimum-error cuts (step 5 of :mod:`dynatex.analyzer.tiles`): dynamic programming along
closed paths, smoothed and cross-faded, and the toroidal tile they make of a looped block.
"""

from __future__ import annotations

import numpy as np

from ...errors import InvalidArgumentError
from .loop import PRE_FRAMES, SAMPLE_FRAMES, Texture, block_starts, even_sample, lively_first

MAX_STEP = 3


def path_steps(flow_rows: np.ndarray, flow_gain: float) -> np.ndarray:
    return np.clip(1 + np.round(flow_gain * flow_rows), 1, MAX_STEP).astype(np.int64)


# -- 5. dynamic-programming cuts ---------------------------------------------------------------
def dp_path(
    err: np.ndarray, steps: np.ndarray, start: np.ndarray | None, move: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """Minimum path through ``err (n, m)`` moving at most ``steps[i]`` columns per row.

    ``start``: allowed start columns (None: any). ``move (n,)``: cost per column moved on
    entering row ``i`` (the edges a step exposes across the path). Returns the column per
    row and the mean error (``err`` along the path only).
    """
    n, m = err.shape
    big = np.float64(1e30)
    acc = np.where(np.zeros(m, bool) if start is None else ~start, big, 0.0) + err[0]
    back = np.zeros((n, m), np.int64)
    cols = np.arange(m)
    for i in range(1, n):
        s = int(steps[i])
        best = np.full(m, big)
        arg = cols.copy()
        for d in range(-s, s + 1):
            src = cols + d
            ok = (src >= 0) & (src < m)
            cand = np.where(ok, acc[np.clip(src, 0, m - 1)], big)
            if move is not None and d:
                cand = cand + abs(d) * move[i]
            better = cand < best
            best = np.where(better, cand, best)
            arg = np.where(better, np.clip(src, 0, m - 1), arg)
        acc = best + err[i]
        back[i] = arg
    path = np.empty(n, np.int64)
    path[-1] = int(np.argmin(acc))
    for i in range(n - 1, 0, -1):
        path[i - 1] = back[i, path[i]]
    return path, float(err[np.arange(n), path].mean())


def circular_cut(err: np.ndarray, steps: np.ndarray, move: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Closed minimum path through ``err (n, m)``: the last row's column is within the first
    row's step of the first row's column (the path is periodic in the row index).
    ``move``: see :func:`dp_path`."""
    n, m = err.shape
    best = (np.inf, None)
    for c0 in range(m):
        start = np.zeros(m, bool)
        start[c0] = True
        e = err.copy()
        s0 = int(steps[0])
        far = np.abs(np.arange(m) - c0) > s0
        e[-1, far] = 1e30
        path, cost = dp_path(e, steps, start, move)
        if move is not None:
            cost += float((np.abs(np.diff(path)) * move[1:]).sum()) / n
        if cost < best[0]:
            best = (cost, path)
    return best[1], best[0]


CUT_SMOOTH = 2.5  # rows: Gaussian smoothing of a cut path before it is drawn (no stair-step teeth)
CUT_SOFT = 3.0  # pixels: width of the cross-fade across a cut that is otherwise hard


def smooth_path(path: np.ndarray, sigma: float = CUT_SMOOTH, *, circular: bool = False) -> np.ndarray:
    """A cut path (a column per row) Gaussian-smoothed along the rows, as real columns.

    A minimum-error path moves by whole pixels from row to row; drawn as it is, every move
    is a stair-step tooth along the cut. Smoothed (periodically for a closed path) it runs
    straight or curves gently between its moves.

    Examples
    --------
    >>> smooth_path(np.array([2, 2, 2, 5, 5, 5]), 1.0).round(1).tolist()
    [2.0, 2.2, 2.9, 4.1, 4.8, 5.0]
    """
    p = np.asarray(path, np.float64)
    if sigma <= 0 or len(p) < 2:
        return p.copy()
    r = int(np.ceil(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    padded = np.pad(p, r, mode="wrap" if circular else "edge")
    return np.convolve(padded, k, mode="valid")


def path_alpha(
    path: np.ndarray,
    m: int,
    *,
    fade: float,
    start: float = 0.5,
    lo: int = 0,
    hi: int | None = None,
    circular: bool = False,
    sigma: float = CUT_SMOOTH,
) -> np.ndarray:
    """Share ``(n, m)`` of the side before a cut: ``path[i]`` is row ``i``'s first pixel past it.

    The path is smoothed (:func:`smooth_path`, kept within ``lo .. hi``) and the share falls
    linearly across it, from ``start`` at the cut by ``1 / fade`` a pixel (``start=0.5``: a
    cross-fade ``fade`` pixels wide centred on the cut; ``start=1``: the side before the cut
    kept whole, fading out beyond it). Columns before ``lo`` are 1 and from ``hi`` on 0.

    Examples
    --------
    >>> path_alpha(np.array([2, 2]), 4, fade=2.0).round(2).tolist()     # two pixels across the cut
    [[1.0, 0.75, 0.25, 0.0], [1.0, 0.75, 0.25, 0.0]]
    """
    hi = m if hi is None else hi
    p = np.clip(smooth_path(path, sigma, circular=circular), lo, hi)
    x = np.arange(m)[None, :] + 0.5
    alpha = np.clip(start - (x - p[:, None]) / max(fade, 1e-6), 0.0, 1.0)
    alpha[:, :lo] = 1.0
    alpha[:, hi:] = 0.0
    return alpha


def toroidal_tile(
    block: np.ndarray, th: int, tw: int, *, flow: np.ndarray | None = None, flow_gain: float = 0.5
) -> tuple[np.ndarray, float, float]:
    """Cut a ``(L, th + b, tw + b, 3)`` looped block into a ``(L, th, tw, 3)`` tile that tiles the plane.

    Returns ``(tile, cost_h, cost_v)``: mean squared RGB error per frame along the cuts.
    ``flow`` ``(th + b, tw + b)`` widens the per-row freedom of the paths.
    """
    length, hb, wb = block.shape[:3]
    by, bx = hb - th, wb - tw
    if by < 2 or bx < 2:
        raise InvalidArgumentError(f"block must exceed the tile by at least 2 pixels, got {hb}x{wb} for {th}x{tw}")
    u = even_sample(length, SAMPLE_FRAMES)
    sub = block[u].astype(np.float32)
    flow = np.zeros((hb, wb), np.float32) if flow is None else flow
    # horizontal wrap: column x of the tile is block column x + tw left of the cut (continuing
    # the right edge), block column x from the cut on. Rows y and y + th share one cut.
    d = sub[:, :, tw : tw + bx] - sub[:, :, :bx]
    eh = (d * d).sum(axis=(0, 3)) / len(u)  # (hb, bx)
    e_rows = eh[:th].copy()
    e_rows[:by] += eh[th : th + by]
    e_rows[:, 0] = 1e30  # cut >= 1: column 0 continues column tw - 1
    steps = path_steps(flow[:th, :bx].mean(axis=1), flow_gain)
    cut_h, cost_h = circular_cut(e_rows, steps)
    # column 0 continues column tw - 1, and columns from bx on have no shifted twin: the
    # smoothed cut cross-fades the two inside 1 .. bx
    a = path_alpha(cut_h, tw, fade=min(CUT_SOFT, bx / 2), lo=1, hi=bx, circular=True)
    a = np.concatenate([a, a[:by]])[None, :, :, None]  # (1, hb, tw, 1)
    mid = np.rint(a * _shift_cols(block, tw) + (1 - a) * block[:, :, :tw]).astype(np.uint8)
    # vertical wrap on the x-periodic intermediate (hb, tw): a closed path in x.
    subm = mid[u].astype(np.float32)
    d = subm[:, th : th + by] - subm[:, :by]
    ev = (d * d).sum(axis=(0, 3)).T / len(u)  # (tw, by)
    ev[:, 0] = 1e30
    steps = path_steps(flow[:by, :tw].mean(axis=0), flow_gain)
    cut_v, cost_v = circular_cut(ev, steps)
    a = path_alpha(cut_v, th, fade=min(CUT_SOFT, by / 2), lo=1, hi=by, circular=True).T[None, :, :, None]
    tile = np.rint(a * _shift_rows(mid, th) + (1 - a) * mid[:, :th]).astype(np.uint8)
    return np.ascontiguousarray(tile), cost_h, cost_v


def _shift_cols(block: np.ndarray, tw: int) -> np.ndarray:
    """``block[:, :, x + tw]`` for ``x < tw`` where it exists (only the first ``b`` columns are used)."""
    out = np.zeros_like(block[:, :, :tw])
    n = block.shape[2] - tw
    out[:, :, :n] = block[:, :, tw:]
    return out


def _shift_rows(block: np.ndarray, th: int) -> np.ndarray:
    out = np.zeros_like(block[:, :th])
    n = block.shape[1] - th
    out[:, :n] = block[:, th:]
    return out


def primary_tile(tx: Texture, th: int, tw: int, by: int, bx: int, flow_gain: float):
    """Best toroidal tile of one texture: rank positions by a cheap bound, cut the best three."""
    f = tx.frames
    h, w = f.shape[1:3]
    hb, wb = th + by, tw + bx
    stride_y, stride_x = max(4, th // 4), max(4, tw // 4)
    ys, xs = block_starts(h, hb, stride_y), block_starts(w, wb, stride_x)
    u = even_sample(tx.length, PRE_FRAMES)
    act = tx.activity
    ranked = []
    for y in ys:
        for x in xs:
            blk = tx.block(y, x, hb, wb, u).astype(np.float32)
            dh = blk[:, :th, tw : tw + bx] - blk[:, :th, :bx]
            dv = blk[:, th : th + by, :tw] - blk[:, :by, :tw]
            bound = (dh * dh).sum(axis=(0, 3)).min(axis=1).mean() + (dv * dv).sum(axis=(0, 3)).min(axis=0).mean()
            ranked.append((float(bound), int(y), int(x), float(act[y : y + hb, x : x + wb].mean())))
    ranked = lively_first(ranked)
    best = None
    for _, y, x, _ in ranked[:3]:
        tile, ch, cv = toroidal_tile(
            tx.block(y, x, hb, wb), th, tw, flow=tx.flow[y : y + hb, x : x + wb], flow_gain=flow_gain
        )
        if best is None or ch + cv < best[2][0] + best[2][1]:
            best = (tile, (y, x), (ch, cv))
    return best
