"""Quilting of spatio-temporal cuboids for time-varying textures (rust spreading, honey melting).

Image quilting (Efros & Freeman) where a block is a small spatial patch carried through the
*whole* sequence, so the output keeps the source's temporal evolution. Following the seed
(time-varying-textures, section 5):

- the clip becomes an ``m x n`` pixel-by-time matrix ``X`` (``m = H W`` pixels, ``n = T C``
  values per pixel: every frame, every channel) and its rank-``k`` SVD ``X ~ U_k S_k V_k^T``
  (``k = 15`` by default); the reconstruction error of every rank is reported;
- candidate blocks are compared in the coefficient space ``X V_k = U_k S_k`` (``k`` numbers
  per pixel instead of ``n``): the squared distance there is the distance of the projections
  onto the top-``k`` time basis, so the comparison costs ``k / n`` of the full one;
- a candidate is picked at random among those within ``tolerance`` of the best overlap error;
- the boundary is a minimum-error cut by dynamic programming on the per-pixel overlap error
  summed over the whole sequence, so it is the same cut in every frame;
- blocks may be square or elongated (``block=(h, w)``); the canvas may have any size;
- optional low-pass gain normalisation: the synthesis runs on frames divided by a blurred
  representative frame, and a per-pixel gain puts back a flat (or the source's) gradient.

Only the comparisons use the SVD; the result copies source pixels exactly: it is a per-pixel
source map (plus gain) that the player gathers from the stored frames.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from ..checks import check_frames, check_int
from ..errors import ArgumentTypeError, InvalidArgumentError
from ..tiledb import QuiltModel
from .methods import check_params
from .video import Clip, Progress

DEFAULT_RANK = 15
# 28 rather than 32: on the 128x128 time-lapse clips, 512x512 quilts (seeds 0-5, median
# seam visibility) went 1.26 -> 1.11 on melting honey and 0.87 -> 0.83 on rusting steel
# (24: 1.17 / 0.91; 40: 1.37 on honey): smaller blocks match the honey's slow flicker better.
DEFAULT_BLOCK = 28
DEFAULT_TOLERANCE = 0.1


# -- the pixel-by-time matrix and its SVD ---------------------------------------------------
def pixel_time_matrix(frames: np.ndarray) -> np.ndarray:
    """The ``(H W, T C)`` float32 matrix whose row ``i`` is pixel ``i``'s whole time sequence.

    Examples
    --------
    >>> pixel_time_matrix(np.zeros((5, 4, 6, 3), np.uint8)).shape
    (24, 15)
    """
    frames = check_frames(frames, name="clip", min_frames=2, uint8=True)
    t, h, w, c = frames.shape
    return np.ascontiguousarray(frames.transpose(1, 2, 0, 3).reshape(h * w, t * c), dtype=np.float32)


def time_svd(matrix: np.ndarray, rank: int | None = DEFAULT_RANK) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank-``k`` SVD of a pixel-by-time matrix through its small Gram matrix.

    Parameters
    ----------
    matrix : (m, n) array
        Pixel-by-time matrix (:func:`pixel_time_matrix`).
    rank : int or None
        Number of components kept in the returned coefficients (``None``: all).

    Returns
    -------
    coefficients : (m, k) float32
        ``X V_k = U_k S_k``: each pixel's time sequence in the top-``k`` time basis.
    singular_values : (r,) float64
        All ``r = min(m, n)`` singular values, descending.
    rank_error : (r,) float64
        ``||X - X_k||_F / ||X||_F`` for ``k = 1 .. r`` (the seed's Figure 5, as a fraction).

    Examples
    --------
    >>> x = np.outer(np.arange(1, 7), np.ones(4)).astype(np.float32)     # rank 1
    >>> coef, s, err = time_svd(x, rank=2)
    >>> coef.shape, bool(err[0] < 1e-6)
    ((6, 2), True)
    """
    x = np.asarray(matrix, dtype=np.float32)
    if x.ndim != 2 or x.size == 0:
        raise InvalidArgumentError(f"matrix must be a non-empty 2-D array, not shape {x.shape}")
    m, n = x.shape
    r = min(m, n)
    if rank is None:
        rank = r
    rank = check_int("rank", rank, 1, r)
    if n <= m:
        gram = x.T.astype(np.float64) @ x.astype(np.float64)
        evals, evecs = np.linalg.eigh(gram)
        order = np.argsort(evals)[::-1]
        evals = np.clip(evals[order], 0, None)
        v = evecs[:, order[:rank]].astype(np.float32)
        coef = x @ v
    else:
        gram = x.astype(np.float64) @ x.T.astype(np.float64)
        evals, evecs = np.linalg.eigh(gram)
        order = np.argsort(evals)[::-1]
        evals = np.clip(evals[order], 0, None)
        s = np.sqrt(evals[:rank])
        coef = (evecs[:, order[:rank]] * s).astype(np.float32)  # U_k S_k
    total = float(evals.sum())
    tail = np.concatenate([np.cumsum(evals[::-1])[::-1][1:], [0.0]])
    err = np.sqrt(np.clip(tail, 0, None) / total) if total > 0 else np.zeros(r)
    return np.ascontiguousarray(coef), np.sqrt(evals), np.minimum.accumulate(err)


def rank_errors(frames: np.ndarray) -> np.ndarray:
    """Relative RMS reconstruction error of the rank-``k`` approximation of the clip, ``k = 1 .. r``.

    Examples
    --------
    >>> f = np.full((6, 4, 4, 3), 90, np.uint8)
    >>> float(rank_errors(f)[0]) < 1e-6
    True
    """
    return time_svd(pixel_time_matrix(frames), rank=1)[2]


# -- block comparison ----------------------------------------------------------------------
def block_errors(features: np.ndarray, template: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Masked sum of squared differences between ``template`` and every block of ``features``.

    Parameters
    ----------
    features : (H, W, k) float32
        Per-pixel feature vectors of the source (SVD coefficients or full time sequences).
    template : (bh, bw, k) float32
        What the output already holds where the next block goes.
    mask : (bh, bw) bool
        The overlap: pixels that take part in the comparison.

    Returns
    -------
    (H - bh + 1, W - bw + 1) float32
        ``E[y, x] = sum over masked pixels of ||features[y + i, x + j] - template[i, j]||^2``.

    Examples
    --------
    >>> f = np.arange(16, dtype=np.float32).reshape(4, 4, 1)
    >>> e = block_errors(f, f[1:3, 1:3], np.ones((2, 2), bool))
    >>> np.argwhere(e == e.min())[0].tolist()
    [1, 1]
    """
    import cv2

    k = features.shape[2]
    m = np.ascontiguousarray(np.repeat(mask[:, :, None].astype(np.float32), k, axis=2))
    out = None
    # OpenCV takes at most 128 channels here; wider features are compared in slices.
    for lo in range(0, k, 128):
        hi = min(k, lo + 128)
        e = cv2.matchTemplate(
            np.ascontiguousarray(features[:, :, lo:hi]),
            np.ascontiguousarray(template[:, :, lo:hi]),
            cv2.TM_SQDIFF,
            mask=np.ascontiguousarray(m[:, :, lo:hi]),
        )
        out = e if out is None else out + e
    assert out is not None
    return np.maximum(out, 0)


def min_cut_path(err: np.ndarray) -> np.ndarray:
    """Minimum-error path from top to bottom through ``err`` (rows x cols), by dynamic programming.

    Returns the column of the path in every row; consecutive rows differ by at most one.

    Examples
    --------
    >>> e = np.ones((4, 3)); e[:, 1] = 0
    >>> min_cut_path(e).tolist()
    [1, 1, 1, 1]
    """
    err = np.asarray(err, dtype=np.float64)
    rows, cols = err.shape
    cost = err.copy()
    for i in range(1, rows):
        prev = cost[i - 1]
        best = prev.copy()
        if cols > 1:
            best[1:] = np.minimum(best[1:], prev[:-1])
            best[:-1] = np.minimum(best[:-1], prev[1:])
        cost[i] += best
    path = np.empty(rows, np.int64)
    path[-1] = int(np.argmin(cost[-1]))
    for i in range(rows - 2, -1, -1):
        j = path[i + 1]
        lo, hi = max(0, j - 1), min(cols, j + 2)
        path[i] = lo + int(np.argmin(cost[i, lo:hi]))
    return path


# -- gain normalisation --------------------------------------------------------------------
def lowpass_reference(frames: np.ndarray, sigma: float, *, reference: str | int = "mean") -> np.ndarray:
    """Low-frequency gradient of a representative frame: ``(H, W, C)`` float32, >= 1.

    ``reference`` is ``"mean"`` (the time average), ``"middle"``, or a frame index.
    """
    import cv2

    t = frames.shape[0]
    if reference == "mean":
        rep = frames.mean(axis=0, dtype=np.float64).astype(np.float32)
    elif reference == "middle":
        rep = frames[t // 2].astype(np.float32)
    elif isinstance(reference, (int, np.integer)) and not isinstance(reference, bool) and 0 <= reference < t:
        rep = frames[int(reference)].astype(np.float32)
    else:
        raise InvalidArgumentError(
            f"reference must be 'mean', 'middle' or a frame index in [0, {t}), not {reference!r}"
        )
    low = cv2.GaussianBlur(rep, (0, 0), sigmaX=float(sigma), borderType=cv2.BORDER_REFLECT)
    return np.maximum(low.reshape(rep.shape), 1.0)


def frame_weights(frames: np.ndarray) -> np.ndarray:
    """Per-frame weights ``1 / g_t``, ``g_t`` the RMS neighbour difference of frame ``t``, normalised to mean 1.

    Examples
    --------
    >>> f = np.zeros((2, 4, 4, 1), np.float32); f[0, :, ::2] = 10; f[1, :, ::2] = 20
    >>> [round(float(v), 3) for v in frame_weights(f)]
    [1.333, 0.667]
    """
    f = np.asarray(frames, dtype=np.float32)
    g = np.sqrt(
        0.5 * (np.square(np.diff(f, axis=1)).mean(axis=(1, 2, 3)) + np.square(np.diff(f, axis=2)).mean(axis=(1, 2, 3)))
    )
    g = np.maximum(g, 1e-3 * max(float(g.max()), 1e-6) + 1e-6)
    wts = 1.0 / g
    return (wts / wts.mean()).astype(np.float32)


# -- quilting --------------------------------------------------------------------------------
def learn_quilt(
    clip: Clip | np.ndarray,
    *,
    size: Sequence[int] | None = None,
    block: int | Sequence[int] = DEFAULT_BLOCK,
    overlap: int | Sequence[int] | None = None,
    rank: int | None = DEFAULT_RANK,
    tolerance: float = DEFAULT_TOLERANCE,
    lowpass: float | None = None,
    restore_gradient: bool = False,
    balance: bool = False,
    feather: int | None = None,
    seed: int = 0,
    progress: Progress | None = None,
) -> QuiltModel:
    """Quilt a time-varying texture onto a canvas of any size with spatio-temporal cuboids.

    Parameters
    ----------
    clip : Clip or ndarray
        Frames ``(T, H, W, C)`` uint8.
    size : (height, width), optional
        Output canvas (default: four times the source area, ``(2 H, 2 W)``).
    block : int or (height, width)
        Block size in source pixels (default 28); elongated blocks (e.g. ``(64, 16)``) suit textures whose
        features stretch over time (growing grass). Must fit the source.
    overlap : int or (oy, ox), optional
        Overlap of neighbouring blocks (default 5/16 of the block, at least 2: room for the
        cut and its cross-fade); each must be at least 1 and at most half the block side.
    rank : int or None
        SVD rank of the comparisons (default 15); ``None`` compares full time sequences
        (the slow baseline the SVD speeds up).
    tolerance : float
        Candidates whose overlap error is within ``(1 + tolerance)`` of the best are picked
        among at random (0: always the best).
    lowpass : float, optional
        Gaussian sigma in pixels of the low-pass gain normalisation (off when ``None``). The
        search then runs on frames divided by the blurred time-average frame and the model
        stores a per-pixel gain that makes the output's low frequencies flat.
    restore_gradient : bool
        With ``lowpass``: the gain puts back the source's low-frequency gradient, stretched
        to the canvas, instead of flattening it.
    balance : bool
        Weight each frame by its own contrast (:func:`frame_weights`) in the comparisons and
        cuts, so that seams are hidden in smooth frames as well as in busy ones.
    feather : int, optional
        Default half the overlap. Half-width in pixels of a cross-fade across each cut (0: hard cuts, as in the seed).
        Pixels within the band store a second source and its weight; the player blends them.
    seed : int
        Seed of the random choices; the same seed gives the same quilt.
    progress : callable(done, total), optional
        Called after each placed block.

    Returns
    -------
    QuiltModel
        Per-pixel source map, block labels, gain, singular values and the error per rank.
        ``info`` holds the parameters, ``rank_error`` (error at the rank used), the
        comparison feature width and the timings.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clip = (rng.random((8, 24, 24, 3)) * 255).astype(np.uint8)
    >>> q = learn_quilt(clip, size=(30, 40), block=8, rank=4)
    >>> q.source_map.shape, q.labels.shape
    ((30, 40, 2), (30, 40))
    """
    size, block, overlap, rank, tolerance, lowpass, restore_gradient, balance, feather, seed = check_params(
        "quilt",
        size=size,
        block=block,
        overlap=overlap,
        rank=rank,
        tolerance=tolerance,
        lowpass=lowpass,
        restore_gradient=restore_gradient,
        balance=balance,
        feather=feather,
        seed=seed,
    )
    frames = check_frames(clip.frames if isinstance(clip, Clip) else clip, name="clip", min_frames=2, uint8=True)
    t, h, w, c = frames.shape
    bh, bw = _pair("block", block, 2)
    if bh > h or bw > w:
        raise InvalidArgumentError(f"block {bw}x{bh} (width x height) is larger than the {w}x{h} source")
    if overlap is None:
        oy, ox = max(2, round(bh * 5 / 16)), max(2, round(bw * 5 / 16))
        oy, ox = min(oy, bh // 2), min(ox, bw // 2)
    else:
        oy, ox = _pair("overlap", overlap, 1)
        if oy > bh // 2 or ox > bw // 2:
            raise InvalidArgumentError(f"overlap {(oy, ox)} must be at most half the block {(bh, bw)} on each side")
    out_h, out_w = (2 * h, 2 * w) if size is None else size
    if feather is None:
        feather = min(oy, ox) // 2
    feather = check_int("feather", feather, 0, min(oy, ox))
    if rank is not None:
        rank = check_int("rank", rank, 1, min(h * w, t * c))
    rng = np.random.default_rng(seed)
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    work = frames
    low = None
    if lowpass is not None:
        low = lowpass_reference(frames, lowpass)
        work = frames.astype(np.float32) * (low.mean(axis=(0, 1)) / low)
    if balance:
        # Each frame counts by its own contrast: a brightness step that is small against the
        # busy early frames of a clip but large against its smooth late frames still shows.
        work = work.astype(np.float32) * frame_weights(work)[:, None, None, None]
    x = np.ascontiguousarray(work.transpose(1, 2, 0, 3).reshape(h * w, t * c), dtype=np.float32)
    coef, sv, err = time_svd(x, rank=rank if rank is not None else 1)
    features = (coef if rank is not None else x).reshape(h, w, -1)
    xfull = x
    timings["svd_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    sy, sx = bh - oy, bw - ox
    nby = max(1, -(-(out_h - oy) // sy))
    nbx = max(1, -(-(out_w - ox) // sx))
    ph, pw = nby * sy + oy, nbx * sx + ox
    k = features.shape[2]
    canvas = np.zeros((ph, pw, k), np.float32)
    smap = np.zeros((ph, pw, 2), np.int32)
    labels = np.zeros((ph, pw), np.int32)
    n_blocks = nby * nbx
    bsrc = np.zeros((n_blocks, 2), np.int32)
    bpos = np.zeros((n_blocks, 2), np.int32)
    yy, xx = np.mgrid[0:bh, 0:bw].astype(np.int32)
    bmap = np.zeros((ph, pw, 2), np.int32)
    blab = np.zeros((ph, pw), np.int32)
    bweight = np.zeros((ph, pw), np.float32)
    compare_s = 0.0
    for i in range(nby):
        for j in range(nbx):
            b = i * nbx + j
            py, px = i * sy, j * sx
            region = (slice(py, py + bh), slice(px, px + bw))
            if i == 0 and j == 0:
                y0, x0 = int(rng.integers(0, h - bh + 1)), int(rng.integers(0, w - bw + 1))
                new = np.ones((bh, bw), bool)
            else:
                mask = np.zeros((bh, bw), bool)
                if j > 0:
                    mask[:, :ox] = True
                if i > 0:
                    mask[:oy, :] = True
                tc = time.perf_counter()
                e = block_errors(features, canvas[region], mask)
                compare_s += time.perf_counter() - tc
                best = float(e.min())
                cand = np.flatnonzero(e.ravel() <= best * (1.0 + tolerance) + 1e-6 * (1.0 + best))
                y0, x0 = np.unravel_index(int(cand[rng.integers(0, cand.size)]), e.shape)
                y0, x0 = int(y0), int(x0)
                # The cut uses the full time sequences (cheap: overlap pixels only), so it is
                # exact; the SVD only ranks the candidates.
                perr = np.zeros((bh, bw), np.float32)
                old = smap[region][mask]
                diff = xfull[old[:, 0] * w + old[:, 1]] - xfull[(yy[mask] + y0) * w + xx[mask] + x0]
                perr[mask] = np.einsum("ij,ij->i", diff, diff)
                new = np.ones((bh, bw), bool)
                if j > 0:
                    cut = min_cut_path(perr[:, :ox])
                    new &= np.arange(bw)[None, :] >= cut[:, None]
                if i > 0:
                    cut = min_cut_path(perr[:oy, :].T)
                    new &= np.arange(bh)[:, None] >= cut[None, :]
            src_here = np.stack([yy + y0, xx + x0], axis=-1)
            if feather and (i > 0 or j > 0):
                _feather(
                    new,
                    mask,
                    feather,
                    smap[region],
                    labels[region],
                    src_here,
                    b,
                    bmap[region],
                    blab[region],
                    bweight[region],
                )
            else:
                bweight[region][new] = 0.0
            canvas[region][new] = features[y0 : y0 + bh, x0 : x0 + bw][new]
            smap[region][new] = src_here[new]
            labels[region][new] = b
            bsrc[b] = (y0, x0)
            bpos[b] = (py, px)
            if progress:
                progress(b + 1, n_blocks)
    timings["quilt_s"] = time.perf_counter() - t0
    timings["compare_s"] = compare_s

    smap = np.ascontiguousarray(smap[:out_h, :out_w])
    labels = np.ascontiguousarray(labels[:out_h, :out_w])
    gain = None
    if low is not None:
        src_low = low[smap[..., 0], smap[..., 1]]
        if restore_gradient:
            import cv2

            target = cv2.resize(low, (out_w, out_h), interpolation=cv2.INTER_LINEAR).reshape(out_h, out_w, c)
        else:
            target = np.broadcast_to(low.mean(axis=(0, 1)), (out_h, out_w, c))
        gain = np.clip(target / src_low, 1.0 / 64, 64.0).astype(np.float32)
    used_rank = rank if rank is not None else min(h * w, t * c)
    info = {
        "block_h": bh,
        "block_w": bw,
        "overlap_y": oy,
        "overlap_x": ox,
        "rank": int(used_rank),
        "compare_width": int(k),
        "full_width": int(t * c),
        "tolerance": tolerance,
        "seed": seed,
        "lowpass": float(lowpass or 0.0),
        "feather": feather,
        "balance": bool(balance),
        "restore_gradient": bool(restore_gradient),
        "rank_error": float(err[used_rank - 1]),
        "blocks_x": nbx,
        "blocks_y": nby,
        **{k_: float(v) for k_, v in timings.items()},
    }
    blend = None
    if feather:
        blend = (
            np.ascontiguousarray(bmap[:out_h, :out_w]),
            np.ascontiguousarray(blab[:out_h, :out_w]),
            np.ascontiguousarray(bweight[:out_h, :out_w]),
        )
    return QuiltModel(
        source_map=smap,
        labels=labels,
        block_sources=bsrc,
        block_positions=bpos,
        singular_values=sv,
        rank_error=err,
        gain=gain,
        blend_map=None if blend is None else blend[0],
        blend_labels=None if blend is None else blend[1],
        blend_weight=None if blend is None else blend[2],
        info=info,
    )


def _feather(
    new: np.ndarray,
    overlap: np.ndarray,
    feather: int,
    old_src: np.ndarray,
    old_lab: np.ndarray,
    new_src: np.ndarray,
    b: int,
    bmap: np.ndarray,
    blab: np.ndarray,
    bweight: np.ndarray,
) -> None:
    """Cross-fade ``feather`` pixels either side of the cut inside the overlap (views are updated in place).

    A pixel at distance ``d`` from the other side of the cut takes weight
    ``max(0, 1/2 - (d - 1/2) / (2 feather))`` of the other side's source.
    """
    import cv2

    d_new = cv2.distanceTransform(new.astype(np.uint8), cv2.DIST_L2, 3)  # new px -> nearest old
    d_old = cv2.distanceTransform((~new).astype(np.uint8), cv2.DIST_L2, 3)  # old px -> nearest new
    w_other = np.clip(0.5 - (np.where(new, d_new, d_old) - 0.5) / (2.0 * feather), 0.0, 0.5)
    has_old = overlap & (w_other > 0)
    take_new = new & has_old  # new primary, old source as secondary
    keep_old = ~new & has_old  # old primary, new source as secondary
    bmap[take_new] = old_src[take_new]
    blab[take_new] = old_lab[take_new]
    bweight[new] = 0.0
    bweight[take_new] = w_other[take_new]
    bmap[keep_old] = new_src[keep_old]
    blab[keep_old] = b
    bweight[keep_old] = w_other[keep_old]


def measure_comparison_speedup(
    frames: np.ndarray,
    *,
    rank: int = DEFAULT_RANK,
    block: int | Sequence[int] = DEFAULT_BLOCK,
    overlap: int | None = None,
    trials: int = 20,
    seed: int = 0,
) -> dict:
    """Time the block comparison in SVD coefficient space against full time sequences.

    Runs the same ``trials`` overlap comparisons (random templates, L-shaped overlaps) on
    both feature sets and reports the median time of each, their ratio, and how often the
    best candidate is the same block.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> r = measure_comparison_speedup((rng.random((20, 24, 24, 3)) * 255).astype(np.uint8), rank=4, block=8, trials=2)
    >>> sorted(r)[:3]
    ['best_agreement', 'full_s', 'full_width']
    """
    frames = check_frames(frames, name="clip", min_frames=2, uint8=True)
    t, h, w, c = frames.shape
    bh, bw = _pair("block", block, 2)
    if bh > h or bw > w:
        raise InvalidArgumentError(f"block {bw}x{bh} (width x height) is larger than the {w}x{h} source")
    o = overlap or max(2, round(min(bh, bw) / 6))
    trials = check_int("trials", trials, 1)
    x = pixel_time_matrix(frames)
    t0 = time.perf_counter()
    coef, _, err = time_svd(x, rank=rank)
    svd_s = time.perf_counter() - t0
    full = x.reshape(h, w, -1)
    small = coef.reshape(h, w, -1)
    rng = np.random.default_rng(seed)
    mask = np.zeros((bh, bw), bool)
    mask[:, :o] = True
    mask[:o, :] = True
    times_small, times_full, agree = [], [], 0
    for _ in range(trials):
        y0, x0 = int(rng.integers(0, h - bh + 1)), int(rng.integers(0, w - bw + 1))
        ta = time.perf_counter()
        es = block_errors(small, small[y0 : y0 + bh, x0 : x0 + bw], mask)
        times_small.append(time.perf_counter() - ta)
        ta = time.perf_counter()
        ef = block_errors(full, full[y0 : y0 + bh, x0 : x0 + bw], mask)
        times_full.append(time.perf_counter() - ta)
        # the template is a source block, so both should find it (error 0) or a tie
        agree += int(np.argmin(ef) == np.argmin(es) or ef.ravel()[np.argmin(es)] <= ef.min() * 1.01 + 1e-3)
    ms, mf = float(np.median(times_small)), float(np.median(times_full))
    return {
        "rank": int(coef.shape[1]),
        "full_width": int(x.shape[1]),
        "svd_s": svd_s,
        "svd_s_per_trial_break_even": svd_s / max(mf - ms, 1e-12),
        "rank_error": float(err[coef.shape[1] - 1]),
        "small_s": ms,
        "full_s": mf,
        "speedup": mf / ms,
        "best_agreement": agree / trials,
    }


def spreading_clip(t: int = 48, h: int = 48, w: int = 64, *, seed: int = 0) -> np.ndarray:
    """A synthetic time-varying texture: rust-like spots spread over grainy steel as time goes on.

    A smooth random field is compared with a level that rises over the clip; pixels below
    it turn dark orange, so spots appear, grow and merge. ``(t, h, w, 3)`` uint8.

    Examples
    --------
    >>> f = spreading_clip(10, 16, 16)
    >>> f.shape, bool(f[-1].mean() < f[0].mean())
    ((10, 16, 16, 3), True)
    """
    t, h, w = check_int("t", t, 2), check_int("h", h, 1), check_int("w", w, 1)
    rng = np.random.default_rng(check_int("seed", seed, 0))
    field = rng.random((h, w))
    for _ in range(2):
        field = (
            field + np.roll(field, 1, 0) + np.roll(field, 1, 1) + np.roll(field, -1, 0) + np.roll(field, -1, 1)
        ) / 5
    field = (field - field.min()) / max(float(np.ptp(field)), 1e-12)
    level = np.linspace(0, 1, t)[:, None, None]
    rust = np.clip((level - field) * 6, 0, 1)
    grain = rng.normal(0, 6, (h, w))
    base = np.stack([200 - 120 * rust, 200 - 150 * rust, 210 - 180 * rust], axis=-1) + grain[None, ..., None]
    return np.clip(base, 0, 255).astype(np.uint8)


# -- argument checks -------------------------------------------------------------------------
def _pair(name: str, v, lo: int, hi: int | None = None) -> tuple[int, int]:
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        v = (v, v)
    try:
        a, b = v
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{name} must be an integer or a pair of integers, not {v!r}") from None
    return check_int(name, a, lo, hi), check_int(name, b, lo, hi)
