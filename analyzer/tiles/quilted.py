"""The quilted construction (step 6c of :mod:`dynatex.analyzer.tiles`): one large torus quilted
from blocks of the looped clip, cut into cells that the player lays out in torus order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...checks import check_int
from ...errors import InvalidArgumentError
from ...framestats import median_step
from ...tiledb.tiles import TilesModel
from ..quilt import block_errors, min_cut_path
from ..video import Progress
from .cuts import path_alpha, smooth_path
from .loop import STEP_PAIRS, Texture, even_sample, find_loop, progress_steps, transition_map
from .stats import colour_stats, feature_scale, stationarity_info

# -- 6c. quilted torus ------------------------------------------------------------------------------
QUILT_MAX_RUN = 3  # blocks at most taken from one continuous piece of the clip, per direction
QUILT_MIN_PERIOD = 512  # the torus is at least this large (and twice the clip) in each direction
QUILT_MAX_PERIOD = 768  # ... but twice the clip only up to this
QUILT_SMALL_SIDE = 128  # a clip with a shorter side under this gets blocks of at most half its side
QUILT_BLOCK_FEATURES = 4  # a block is this many feature scales wide (within the clip's bounds)
QUILT_OVERLAP_FEATURES = 3  # the overlap is this many feature scales (a quarter to a half of the block)
QUILT_LOW_FEATURES = 2  # the low band (cross-faded over the whole overlap) is coarser than this many
QUILT_MAX_LOOP = 64  # default longest loop of the quilted construction (the torus is stored whole)
_QUILT_FEATURE_FRAMES = 12
_QUILT_COMPONENTS = 8


def quilt_geometry(
    h: int,
    w: int,
    *,
    block: int | None = None,
    period: Sequence[int] | None = None,
    scale: float | None = None,
) -> tuple[int, int, tuple[int, int], tuple[int, int]]:
    """``(block, step, cell, period)`` of the quilted torus for an ``h x w`` clip whose largest
    coherent features are ``scale`` pixels across (:func:`.stats.feature_scale`).

    The block (default :data:`QUILT_BLOCK_FEATURES` feature scales, rounded to 8) stays within
    bounds set by the clip: at least 16 pixels, at most half the shorter side (so enough clip
    places are left to choose among) on a clip under :data:`QUILT_SMALL_SIDE` pixels, and a
    third of the shorter side (16..128) on a larger clip (which bounds the blocks per torus and
    so the analysis time). Blocks overlap by :data:`QUILT_OVERLAP_FEATURES` feature scales, at
    least a quarter and at most half the block: a fine-grained clip gets small blocks with
    narrow overlaps, a coarse one large blocks whose cuts have room to go round its features.
    Without ``scale``, the coarsest choice. Cells (the player's lattice, the stored tiles) are
    the fewest steps at least 64 pixels wide, so a 64-pixel run of the gather touches at most two
    cells; the period ``(py, px)`` is whole cells, at least 512 pixels (four clip sides for a
    clip under 128 pixels, two cells at least) and twice the clip up to 768 pixels in each
    direction (the torus is stored whole: 768 x 768 x 64 frames is 113 MB) (or ``period``,
    rounded up to whole cells).

    Examples
    --------
    >>> quilt_geometry(64, 64, scale=2.0)[:2], quilt_geometry(64, 64, scale=15.0)[:2]
    ((16, 10), (32, 16))
    """
    side = min(h, w)
    small = side < QUILT_SMALL_SIDE
    hi = max(16, side // 2 // 8 * 8) if small else int(np.clip(round(side / 3 / 8) * 8, 16, 128))
    lo = 16 if small else hi
    feat = float(side) if scale is None else max(0.0, float(scale))
    if block is None:
        block = int(np.clip(round(QUILT_BLOCK_FEATURES * feat / 8) * 8, lo, hi))
        block = max(8, min(block, (side - 2) // 8 * 8))
    block = check_int("block", block, 8)
    if block + 2 > side:
        raise InvalidArgumentError(f"quilt block {block} (plus 2) is larger than the clip frame {h}x{w}")
    overlap = int(np.clip(round(QUILT_OVERLAP_FEATURES * feat), block // 4, block // 2))
    step = block - overlap
    cell = step * -(-64 // step)
    if period is None:
        want = (
            max(min(QUILT_MIN_PERIOD, 4 * h), min(2 * h, QUILT_MAX_PERIOD), 2 * cell),
            max(min(QUILT_MIN_PERIOD, 4 * w), min(2 * w, QUILT_MAX_PERIOD), 2 * cell),
        )
    else:
        try:
            want = tuple(int(v) for v in period)
        except (TypeError, ValueError):
            raise InvalidArgumentError(f"period must be (height, width), not {period!r}") from None
        if len(want) != 2 or min(want) < 2 * cell:
            raise InvalidArgumentError(f"period must be two sides of at least {2 * cell} pixels, not {period!r}")
    py, px = (cell * -(-v // cell) for v in want)
    return block, step, (cell, cell), (py, px)


def _block_alpha(err: np.ndarray, side: str, margin: int, fade: float) -> tuple[np.ndarray, np.ndarray]:
    """Shares ``(B, B)`` of the new block across the minimum cut through the overlap band along
    ``side`` (``err``: the band's per-pixel error, across x for left/right): ``(sharp, wide)``.

    The cut keeps ``margin`` pixels from both edges of the band and is smoothed
    (:func:`.cuts.smooth_path`). ``sharp`` cross-fades ``fade`` pixels wide centred on it;
    ``wide`` rises smoothly across the whole band, from 0 at the old side's edge through 0.5 at
    the cut to 1 at the new side's edge (1 on the new block's side)."""

    err = np.array(err if side in ("left", "right") else err.T, np.float64)  # rows along the cut
    b, o = err.shape
    lo, hi = margin, max(margin + 1, o - margin)
    err[:, :lo], err[:, hi:] = 1e30, 1e30
    smoothed = smooth_path(min_cut_path(err))  # the band's first pixel past the cut
    p = np.clip(smoothed, lo, hi)[:, None]
    x = np.arange(o)[None, :] + 0.5
    u = np.where(x < p, 0.5 * x / p, 0.5 + 0.5 * (x - p) / np.maximum(o - p, 1e-6))
    wide = np.ones((b, b))
    if side in ("left", "top"):  # the band's first pixel past the cut starts the new block
        sharp = 1.0 - path_alpha(smoothed, b, fade=fade, lo=lo, hi=hi, sigma=0.0)
        wide[:, :o] = u * u * (3 - 2 * u)
    else:  # the band sits at the far edge: the new block is before the cut
        sharp = path_alpha(b - o + smoothed + 1, b, fade=fade, lo=b - o + lo, hi=b - o + hi, sigma=0.0)
        wide[:, b - o :] = 1.0 - u * u * (3 - 2 * u)
    if side in ("left", "right"):
        return sharp, wide
    return sharp.T, wide.T


def _blur_matrix(n: int, sigma: float) -> np.ndarray:
    """``(n, n)`` Gaussian smoothing along one axis of length ``n`` (reflected at both ends)."""
    if sigma <= 0:
        return np.eye(n)
    r = np.arange(-n + 1, 2 * n - 1)  # positions reflected into 0 .. n - 1
    src = np.where(r < 0, -r - 1, np.where(r >= n, 2 * n - 1 - r, r))
    k = np.exp(-0.5 * ((np.arange(n)[:, None] - r[None, :]) / sigma) ** 2)
    m = np.zeros((n, n))
    for j in range(n):
        m[:, j] = k[:, src == j].sum(axis=1)
    return m / m.sum(axis=1, keepdims=True)


def _smoother(n: int, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """``(up, down)``, ``(n, k)`` and ``(k, n)`` float32, whose product smooths one axis of length
    ``n`` by a Gaussian of ``sigma`` pixels: ``down`` averages cells of about ``sigma // 2`` pixels and
    smooths them, ``up`` interpolates back (a wide Gaussian costs no more than a narrow one)."""
    f = max(1, int(sigma // 2))
    if f == 1:
        return np.eye(n, dtype=np.float32), _blur_matrix(n, sigma).astype(np.float32)
    k = -(-n // f)
    pool = np.zeros((k, n))
    pool[np.arange(n) * k // n, np.arange(n)] = 1.0  # cells of f or f - 1 pixels
    centres = pool @ np.arange(n) / pool.sum(axis=1)
    pool /= pool.sum(axis=1, keepdims=True)
    up = np.stack([np.interp(np.arange(n), centres, np.eye(k)[i]) for i in range(k)], axis=1)
    return up.astype(np.float32), (_blur_matrix(k, sigma / f) @ pool).astype(np.float32)


def _low_pass(x: np.ndarray, smoother: tuple[np.ndarray, np.ndarray], weight: np.ndarray) -> np.ndarray:
    """``x (L, B, B, 3)`` smoothed in space (:func:`_smoother`) over the pixels of ``weight (B, B)``
    1 only (a normalised convolution: the torus not yet filled does not count).

    Batched matrix products on contiguous views: only the first product reads ``x`` at full size
    and only the last writes it; the middle ones work on ``(L, k, 3, B)`` cells."""
    up, down = smoother
    n, b = x.shape[:2]
    k = down.shape[0]
    y = np.matmul(down, (x * weight[None, :, :, None]).reshape(n, b, b * 3))  # rows: (L, k, B 3)
    y = np.ascontiguousarray(y.reshape(n, k, b, 3).transpose(0, 1, 3, 2))  # (L, k, 3, B)
    y = np.matmul(np.matmul(y, down.T), up.T)  # columns down and up: (L, k, 3, B)
    y = np.matmul(up, np.ascontiguousarray(y.transpose(0, 1, 3, 2)).reshape(n, k, b * 3)).reshape(n, b, b, 3)
    y /= np.maximum(up @ down @ weight @ down.T @ up.T, 1e-6)[None, :, :, None]
    return y


def _window(y: int, x: int, b: int, period: tuple[int, int]) -> tuple:
    """Index of the ``b x b`` torus window at ``(y, x)`` (its last two axes): slices (a view,
    no gather) where it does not wrap, index arrays where it does."""
    ax = [slice(v, v + b) if v + b <= p else (v + np.arange(b)) % p for v, p in zip((y, x), period)]
    if all(isinstance(a, np.ndarray) for a in ax):
        return ax[0][:, None], ax[1][None, :]
    return tuple(ax)


QUILT_REUSE = 4


def _reuse_order(i: int, j: int, nby: int, nbx: int) -> list[tuple[int, int]]:
    """Blocks placed before ``(i, j)`` within :data:`QUILT_REUSE` blocks of it on the torus,
    nearest first."""
    near = []
    for di in range(-QUILT_REUSE, QUILT_REUSE + 1):
        for dj in range(-QUILT_REUSE, QUILT_REUSE + 1):
            if di == dj == 0:
                continue
            ni, nj = (i + di) % nby, (j + dj) % nbx
            near.append((di * di + dj * dj, ni, nj))
    seen, out = set(), []
    for _, ni, nj in sorted(near):
        if (ni, nj) not in seen and (ni, nj) != (i, j):
            seen.add((ni, nj))
            out.append((ni, nj))
    return out


def quilted_torus(
    tx: Texture,
    *,
    block: int | None = None,
    period: Sequence[int] | None = None,
    feather: int | None = None,
    scale: float | None = None,
    low: float | None = None,
    tolerance: float = 0.2,
    seed: int = 0,
    step_done=None,
) -> tuple[np.ndarray, dict]:
    """A large toroidal texture quilted from spatio-temporal blocks of the looped clip.

    Blocks of ``B x B`` pixels carried through the whole loop are placed on a torus
    ``(py, px)`` in raster order (image quilting, Efros & Freeman, of cuboids as in the quilt
    mode): each is the clip place whose sampled loop frames best match what the torus already
    holds in its overlap bands (left and top; the last column also its right band, which wraps
    onto the first column, the last row its bottom band), picked at random among those within
    ``tolerance`` of the best. A block may continue its left or top neighbour's piece of clip
    for at most :data:`QUILT_MAX_RUN` blocks, so the torus is never a tiling of whole clip
    frames. Block, step and the defaults below follow the clip's feature scale ``scale``
    (default :func:`.stats.feature_scale` of the clip; :func:`quilt_geometry`). Each band ends
    at a minimum-error cut (summed over the loop), smoothed, and the blocks meet across it in
    two bands: the detail finer than ``low`` pixels (a Gaussian's sigma; default
    :data:`QUILT_LOW_FEATURES` feature scales) cross-fades over ``2 feather + 1`` pixels centred on
    the cut (default ``feather`` half a feature scale, at most an eighth of the overlap; the cut
    keeps ``feather + 1`` pixels from the band's edges), the coarser rest rises smoothly across
    the whole band, so two blocks of different brightness leave no straight-edged step (``low``
    0: one band). Since the bands wrap, the torus is seamless in x and y; each block loops
    seamlessly in t like the clip's loop.

    Returns ``(torus (L, py, px, 3) uint8, info)``.
    """

    f = tx.frames
    h, w = f.shape[1:3]
    scale = feature_scale(f) if scale is None else float(scale)
    b, step, _, (py, px) = quilt_geometry(h, w, block=block, period=period, scale=scale)
    o = b - step
    fe = int(np.clip(round(scale / 2), 1, max(1, o // 8))) if feather is None else check_int("feather", feather, 0)
    fe = min(fe, (o - 1) // 2)
    low = QUILT_LOW_FEATURES * scale if low is None else float(low)
    smoother = _smoother(b, low) if low > 0 else None
    filled = np.zeros((py, px), bool)
    nby, nbx = py // step, px // step
    length = tx.length
    rng = np.random.default_rng(seed)
    u_feat = even_sample(length, _QUILT_FEATURE_FRAMES)
    u_cut = even_sample(length, 16)
    loop_feat = tx.block(0, 0, h, w, u_feat).astype(np.float32)  # (n, h, w, 3)
    feat = loop_feat.transpose(1, 2, 0, 3).reshape(h * w, -1)
    # the comparisons run on the leading principal components of the sampled frames (a third
    # of the channels: matchTemplate's time is proportional to them)
    mean = feat.mean(axis=0)
    _, _, vt = np.linalg.svd(np.cov((feat - mean)[::7].T).astype(np.float64))
    basis = vt[:_QUILT_COMPONENTS].T.astype(np.float32)
    features = np.ascontiguousarray(((feat - mean) @ basis).reshape(h, w, -1))
    torus = np.zeros((length, py, px, 3), np.uint8)
    src = np.full((nby, nbx, 2), -(10**6), np.int64)
    run_x = np.zeros((nby, nbx), np.int64)
    run_y = np.zeros((nby, nbx), np.int64)
    costs = []
    r_ex = max(1, step // 2)
    src[:] = -1
    for i in range(nby):
        for j in range(nbx):
            win = _window(i * step, j * step, b, (py, px))
            sides = [
                s
                for s, on in (
                    ("left", j > 0),
                    ("top", i > 0),
                    ("right", j == nbx - 1 and nbx > 1),
                    ("bottom", i == nby - 1 and nby > 1),
                )
                if on
            ]
            mask = np.zeros((b, b), bool)
            for s in sides:
                mask[
                    {
                        "left": (slice(None), slice(0, o)),
                        "right": (slice(None), slice(b - o, b)),
                        "top": (slice(0, o), slice(None)),
                        "bottom": (slice(b - o, b), slice(None)),
                    }[s]
                ] = True
            if not sides:
                y0, x0 = int(rng.integers(0, h - b + 1)), int(rng.integers(0, w - b + 1))
                torus[(slice(None), *win)] = tx.block(y0, x0, b, b)
                filled[win] = True
                src[i, j] = (y0, x0)
                if step_done:
                    step_done()
                continue
            old = torus[(slice(None), *win)]
            old_feat = old[u_feat].astype(np.float32)
            template = np.ascontiguousarray(
                ((old_feat.transpose(1, 2, 0, 3).reshape(b * b, -1) - mean) @ basis).reshape(b, b, -1)
            )
            e = block_errors(features, template, mask).astype(np.float64)
            # no piece of clip again within QUILT_REUSE blocks (on the torus), nearest first, as
            # long as a tenth of the places stay open (a motif repeated at a few blocks' lag
            # is a lattice of its own)
            keep_open = max(1, e.size // 10)
            for ni, nj in _reuse_order(i, j, nby, nbx):
                cy, cx = src[ni, nj]
                if cy < 0:
                    continue
                ys, xs = (
                    slice(max(0, cy - r_ex), max(0, cy + r_ex + 1)),
                    slice(max(0, cx - r_ex), max(0, cx + r_ex + 1)),
                )
                open_here = int(np.isfinite(e[ys, xs]).sum())
                if int(np.isfinite(e).sum()) - open_here < keep_open:
                    break
                e[ys, xs] = np.inf
            # a piece of clip continued for QUILT_MAX_RUN blocks ends here
            for (ni, nj), run, (dy, dx) in ((((i, j - 1), run_x, (0, step))), (((i - 1, j), run_y, (step, 0)))):
                if ni >= 0 and nj >= 0 and run[ni, nj] >= QUILT_MAX_RUN - 1:
                    cy, cx = src[ni, nj] + (dy, dx)
                    e[max(0, cy - r_ex) : max(0, cy + r_ex + 1), max(0, cx - r_ex) : max(0, cx + r_ex + 1)] = np.inf
            if not np.isfinite(e).any():  # a tiny clip: every place is excluded
                e = block_errors(features, template, mask).astype(np.float64)
            best = float(e.min())
            cand = np.flatnonzero(e.ravel() <= best * (1.0 + tolerance) + 1e-6 * (1.0 + best))
            if cand.size > 8:
                cand = cand[np.argsort(e.ravel()[cand], kind="stable")[:8]]
            y0, x0 = (int(v) for v in np.unravel_index(int(cand[rng.integers(0, cand.size)]), e.shape))
            new = tx.block(y0, x0, b, b)
            d = new[u_cut].astype(np.float32) - old[u_cut].astype(np.float32)
            perr = (d * d).sum(axis=(0, 3)) / len(u_cut)
            band = {"left": perr[:, :o], "right": perr[:, b - o :], "top": perr[:o, :], "bottom": perr[b - o :, :]}
            sharp, wide = np.ones((b, b)), np.ones((b, b))
            for s in sides:
                sa, wa = _block_alpha(band[s], s, fe + 1, 2.0 * fe + 1.0)
                sharp, wide = np.minimum(sharp, sa), np.minimum(wide, wa)
            keep = sharp >= 0.5
            costs.append(float(perr[mask & keep].mean()) if (mask & keep).any() else 0.0)
            a = sharp.astype(np.float32)[None, :, :, None]
            oldf = old.astype(np.float32)
            d = new - oldf
            out = a * d
            out += oldf
            if smoother is not None:  # the coarse difference fades across the whole overlap
                coarse = _low_pass(d, smoother, filled[win].astype(np.float32))
                coarse *= wide.astype(np.float32)[None, :, :, None] - a
                out += coarse
            torus[(slice(None), *win)] = np.clip(np.rint(out, out=out), 0, 255, out=out)
            filled[win] = True
            src[i, j] = (y0, x0)
            if j > 0 and (y0, x0) == tuple(src[i, j - 1] + (0, step)):
                run_x[i, j] = run_x[i, j - 1] + 1
            if i > 0 and (y0, x0) == tuple(src[i - 1, j] + (step, 0)):
                run_y[i, j] = run_y[i - 1, j] + 1
            if step_done:
                step_done()
    info = {
        "quilt_block": b,
        "quilt_step": step,
        "quilt_feather": fe,
        "quilt_scale": scale,
        "quilt_low": low,
        "period_h": py,
        "period_w": px,
        "quilt_seam_cost": float(np.mean(costs)) if costs else 0.0,
    }
    return torus, info


def torus_cells(torus: np.ndarray, cell: Sequence[int]) -> np.ndarray:
    """The torus cut into cells, row-major: ``(m n, L, ch, cw, 3)`` for an ``(L, m ch, n cw, 3)`` torus."""
    length, py, px, c = torus.shape
    ch, cw = cell
    m, n = py // ch, px // cw
    return np.ascontiguousarray(
        torus.reshape(length, m, ch, n, cw, c).transpose(1, 3, 0, 2, 4, 5).reshape(m * n, length, ch, cw, c)
    )


def learn_quilted(
    main: np.ndarray,
    names: list[str],
    *,
    block: int | None,
    min_loop: int,
    max_loop: int | None,
    transition: int,
    period,
    seed: int,
    progress: Progress | None,
) -> TilesModel:
    """The quilted construction of :func:`~dynatex.analyzer.tiles.learn_tiles` (one texture; its
    arguments checked there)."""
    max_loop = max(min_loop, QUILT_MAX_LOOP) if max_loop is None else max_loop
    t, h, w = main.shape[:3]
    scale = feature_scale(main)
    b, step, cell, (py, px) = quilt_geometry(h, w, block=block, period=period, scale=scale)
    total = 4 + (py // step) * (px // step)
    step_done = progress_steps(progress, total)

    start, length, loop_cost = find_loop(main, min_loop=min_loop, max_loop=max_loop, transition=transition)
    tx = Texture(
        main,
        start,
        length,
        loop_cost,
        transition_map(main, start, length, transition),
        np.zeros(main.shape[1:3], np.float32),
    )
    step_done(2)
    torus, qinfo = quilted_torus(tx, block=b, period=(py, px), scale=scale, seed=seed, step_done=step_done)
    # cells start half a step into the blocks, away from the quilt's overlap bands: a cell
    # border is then plain clip content
    half = step // 2
    qinfo["cell_offset"] = half
    tiles = torus_cells(np.roll(torus, (-half, -half), axis=(1, 2)), cell)
    del torus
    k = len(tiles)
    stats = [colour_stats(tl) for tl in tiles]
    step_done()
    ch, cw = cell
    model = TilesModel(
        tiles=tiles,
        tile_class=np.zeros(k, np.int32),
        ring_class=np.zeros(k, np.int32),
        masks=np.full((k, ch, cw), 255, np.uint8),
        border_side=np.full(k, -1, np.int8),
        seam_cost=np.zeros(k),
        mean_rgb=np.array([st[0] for st in stats]),
        mean_hsv=np.array([st[1] for st in stats]),
        class_names=names,
        class_loop_start=np.array([start], np.int64),
        class_loop_cost=np.array([loop_cost]),
        class_toroid_cost=np.zeros((1, 2)),
        info={
            "construction": "quilted",
            **stationarity_info(main),
            "torus_rows": py // ch,
            "torus_cols": px // cw,
            **qinfo,
            "quilt_seed": seed,
            "tile_h": ch,
            "tile_w": cw,
            "loop_length": length,
            "transition": transition,
            "overlap_y": b - step,
            "overlap_x": b - step,
            "ring": 0,
            "feather": 0,
            "border_depth": 0,
            "ring_feather": 0,
            "period_y": 0.0,
            "period_x": 0.0,
            "periodicity": 0.0,
            "mean_flow": 0.0,
            "flow_gain": 0.0,
            "source_frames": t,
            "n_classes": 1,
            "median_frame_step": median_step(main, pairs=STEP_PAIRS),
        },
    )
    step_done(total)
    return model
