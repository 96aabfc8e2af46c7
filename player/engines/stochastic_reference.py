"""Numpy reference of the stochastic engine (:mod:`.stochastic`) and the tables both share.

The triangle grid (:func:`triangle_cell`, :func:`vertex_grid`, :func:`vertex_pixels`), the blend
weights of one grid cell (:func:`weight_table`), Heitz and Neyret's Gaussianizing tables
(:func:`gauss_tables`), the per-frame vertex table (:func:`vertex_table`) and the frame itself
(:func:`stochastic_reference`), computed as ``kernels/stochastic.cl`` computes it.

>>> t = weight_table((13, 16))
>>> t.shape
(13, 16, 4)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ...errors import InvalidArgumentError

GS = 32  # levels of the Gaussianized torus (bytes, 128 the mean) per standard deviation
STEPS = 16  # entries of the inverse table per level
N_INVERSE = 256 * STEPS  # entries of the inverse table per channel (Gaussian values within +-128 / GS)
WQ = 256  # blend weights in 256ths
BAND = 0.1  # a vertex blends where its barycentric coordinate is within this of the largest


def triangle_cell(torus_shape: Sequence[int]) -> tuple[int, int]:
    """``(row height, width)`` of the triangle grid for a torus: the width half the torus's
    shorter side (even, so odd rows shift by whole pixels), equilateral triangles. A window
    then spans at most the torus (its hexagon is two cells wide)."""
    side = min(int(v) for v in torus_shape)
    w = max(4, (side // 2) // 2 * 2)
    return max(2, int(round(w * math.sqrt(3) / 2))), w


def weight_table(cell: Sequence[int], band: float = BAND) -> np.ndarray:
    """``(ch, cw, 4)`` float32: for each pixel of one grid cell (``ch`` rows of a band, ``cw``
    columns), the blend weights of its triangle's three vertices and ``tri + 4 single``
    (module ``kernels/stochastic.cl`` says which triangle and vertex these name).

    A vertex takes part where its barycentric coordinate is within ``band`` of the pixel's
    largest one: ``s = smoothstep((b - max b + band) / band)``, so each vertex shows its window
    alone over most of its hexagon and windows meet in bands about ``band`` times the cell's
    width wide along the hexagons' edges, their weights rising from 0 with zero slope (no
    edge to the band). A blend takes Heitz and Neyret's variance-preserving weights
    ``s_i / sqrt(sum s_j^2)``; where one weight alone is left in ``WQ``-ths, the window alone
    shows (weights (1, 0, 0) at its place).

    >>> t = weight_table((13, 16), 0.3)
    >>> blend = t[..., 3] < 4
    >>> bool(np.allclose((t[blend][:, :3] ** 2).sum(-1), 1, atol=1e-6)), [int(v) for v in np.unique(t[..., 3] // 4)]
    (True, [0, 1, 2, 3])
    """
    ch, cw = (int(v) for v in cell)
    if ch < 1 or cw < 2 or cw % 2:
        raise InvalidArgumentError(f"cell must be (rows >= 1, even width >= 2), not {tuple(cell)}")
    if not 0.0 < float(band) <= 1.0:
        raise InvalidArgumentError(f"band must be in (0, 1], not {band!r}")
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
    s = np.clip((bary - bary.max(-1, keepdims=True) + float(band)) / float(band), 0.0, 1.0)
    s = s * s * (3.0 - 2.0 * s)
    w = s / np.sqrt((s * s).sum(-1, keepdims=True))
    alone = (np.rint(w * WQ) > 0).sum(-1) == 1
    single = np.where(alone, np.argmax(w, -1) + 1, 0)
    w = np.where(alone[..., None], 0.0, w)
    return np.concatenate([w, (tri + 4 * single)[..., None]], -1).astype(np.float32)


def _normal_cdf(g: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.vectorize(math.erf)(np.asarray(g, np.float64) / math.sqrt(2.0)))


def gauss_tables(hist: np.ndarray, gain: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heitz and Neyret's tables from per-channel value histograms ``hist`` ``(3, 256)``:
    ``T`` ``(3, 256)`` uint8, the standard-normal quantile of each value's mid-rank (a value
    drawn from the histogram comes out standard normal) in bytes, ``128 + rint(GS q)`` saturated
    (the paper stores the transformed input as an 8-bit texture too); ``inverse`` ``(3,
    N_INVERSE)`` uint8, for Gaussian values on a lattice of ``1 / STEPS`` levels from ``-128``,
    the smallest value whose cumulative share reaches the value's normal probability (T's
    inverse, which gives the histogram back); ``tone`` ``(3, 256)`` uint8, a value toned by
    ``gain`` (per channel, default 1; :func:`tone_gains`), which ``inverse`` also holds.

    >>> T, inv, tone = gauss_tables(np.ones((3, 256)))
    >>> int(T[0, 0]) < 60 < 128 - 1 <= int(T[0, 127]) <= 128 < 200 < int(T[0, 255]), int(tone[1, 200])
    (True, 200)
    """
    hist = np.asarray(hist, np.float64)
    if hist.shape != (3, 256) or not np.isfinite(hist).all() or (hist < 0).any() or (hist.sum(1) <= 0).any():
        raise InvalidArgumentError(f"hist must be (3, 256) counts, some in every channel, not {hist.shape}")
    gain = np.ones(3) if gain is None else np.asarray(gain, np.float64)
    cdf = np.cumsum(hist, 1) / hist.sum(1, keepdims=True)
    mid = 0.5 * (cdf + np.concatenate([np.zeros((3, 1)), cdf[:, :-1]], 1))
    grid = np.linspace(-8.0, 8.0, 8193)
    phi = _normal_cdf(grid)
    q = np.stack([np.interp(np.clip(m, 1e-9, 1 - 1e-9), phi, grid) for m in mid])
    table = np.clip(np.rint(q * GS) + 128, 0, 255).astype(np.uint8)
    centres = (np.arange(N_INVERSE) - N_INVERSE // 2) / (STEPS * GS)
    p = _normal_cdf(centres)
    v = np.stack([np.minimum(np.searchsorted(c, p), 255) for c in cdf])
    values = np.arange(256)
    tone = np.minimum(255, (values.astype(np.int64)[None] * tone_gains(gain)[:, None] + 128) >> 8).astype(np.uint8)
    inverse = np.take_along_axis(tone, v, 1).astype(np.uint8)
    return table, inverse, tone


def gaussianize(torus: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The torus ``(..., 3)`` uint8 through the Gaussianizing ``table`` (:func:`gauss_tables`),
    channel by channel: what the blend reads, computed once."""
    out = np.empty_like(torus)
    for ch in range(3):
        out[..., ch] = table[ch][torus[..., ch]]
    return out


def blend_weights(weights: np.ndarray) -> np.ndarray:
    """``(ch, cw, 4)`` int32: :func:`weight_table`'s blend weights in ``WQ``-ths (rounded) and its code."""
    w = np.rint(weights[..., :3].astype(np.float64) * WQ)
    return np.concatenate([w, weights[..., 3:]], -1).astype(np.int32)


def inverse_index(acc: np.ndarray) -> np.ndarray:
    """The inverse table's entry for ``acc``, a blend of Gaussianized levels ``sum W_k d_k`` (``W``
    in ``WQ``-ths, ``d`` the time-interpolated level minus 128 in 255ths), rounded to the nearest
    of ``STEPS`` per level, in shifts and one product (``257 / 4096`` for ``STEPS / 255``)."""
    u = np.asarray(acc, np.int64) + (1 << 25)
    return np.clip((((u >> 8) * 257 + 2048) >> 12) - (8224 - N_INVERSE // 2), 0, N_INVERSE - 1)


def tone_gains(gain: np.ndarray) -> np.ndarray:
    """The tone ``gain`` per channel in 256ths (int64), as the kernel multiplies: a value ``m``
    is toned to ``min(255, (m g + 128) >> 8)``."""
    return np.rint(np.clip(np.asarray(gain, np.float64), 0.0, 255.0) * 256.0).astype(np.int64)


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
    gauss_torus: np.ndarray,
    weights: np.ndarray,
    vertices: np.ndarray,
    inverse: np.ndarray,
    tone: np.ndarray,
    size: Sequence[int],
    *,
    rows: range | None = None,
) -> np.ndarray:
    """Reference of kernels ``stochastic_copy`` and ``stochastic_blend``: ``(len(rows), W, 3)``
    uint8 RGB of the output rows ``rows`` (default all) of an output ``size``, from the ``torus``
    ``(L, TH, TW, 3)``, its :func:`gaussianize` d copy, the cell's ``weights``
    (:func:`weight_table`), the ``vertices`` (:func:`vertex_table`) and the tables
    (:func:`gauss_tables`). The same integers as the kernels."""
    h, w = (int(v) for v in size)
    n, th, tw, _ = torus.shape
    vcols = vertices.shape[1]
    rows = range(h) if rows is None else rows
    flat = torus.reshape(n, th * tw, 3)
    gflat = gauss_torus.reshape(n, th * tw, 3)
    vflat = vertices.reshape(-1, 4).astype(np.int64)
    y = np.arange(rows.start, rows.stop)[:, None] + np.zeros((1, w), np.int64)
    x = np.arange(w)[None, :] + np.zeros((len(rows), 1), np.int64)
    wt, single, vid = pixel_vertices(y, x, weights, vcols)
    wq = blend_weights(wt)[..., :3].astype(np.int64)
    ch3 = np.arange(3)

    def samples(source: np.ndarray, v: np.ndarray, sel: np.ndarray):
        vv = vflat[v]
        p = ((y[sel] + vv[..., 0]) % th) * tw + (x[sel] + vv[..., 1]) % tw
        f = vv[..., 2]
        a = source[f, p].astype(np.int64)
        b = source[np.where(f + 1 == n, 0, f + 1), p].astype(np.int64)
        return a, b, vv[..., 3][..., None]

    out = np.empty((len(rows), w, 3), np.uint8)
    one = single > 0
    if one.any():
        v = np.choose(np.maximum(single - 1, 0), vid)[one]
        a, b, wb = samples(flat, v, one)
        nn = (255 - wb) * a + wb * b + 127
        out[one] = tone[ch3, (nn + 1 + (nn >> 8)) >> 8]
    blend = ~one
    if blend.any():
        acc = np.zeros((int(blend.sum()), 3), np.int64)
        for k in range(3):
            a, b, wb = samples(gflat, vid[k][blend], blend)
            acc += wq[..., k][blend][:, None] * ((255 - wb) * a + wb * b - 128 * 255)
        out[blend] = inverse[ch3, inverse_index(acc)]
    return out
