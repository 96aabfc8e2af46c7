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
   frames by default). Every cut (here and in steps 5-7) is smoothed and
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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..checks import check_int
from ..errors import InvalidArgumentError
from ..tiledb.tiles import (  # the stationarity warning lives with the model that describes it
    CONSTRUCTIONS,
    STATIONARITY_WARN,  # noqa: F401 - re-exported
    TilesModel,
    stationarity_warning,  # noqa: F401 - re-exported
)
from .video import Clip, Progress

DEFAULT_MIN_TILE = 32
DEFAULT_MAX_TILE = 256
MAX_STEP = 3
_SAMPLE_FRAMES = 48  # loop frames summed in the cut errors (evenly spread)
_PRE_FRAMES = 12  # loop frames used to rank candidate positions


# -- 1. tile size ------------------------------------------------------------------------------
def _grey(frames: np.ndarray) -> np.ndarray:
    f = frames.astype(np.float32)
    return f @ np.array([0.299, 0.587, 0.114], np.float32) if f.shape[-1] == 3 else f[..., 0]


def tile_period(
    frames: np.ndarray, *, min_tile: int = DEFAULT_MIN_TILE, max_tile: int = DEFAULT_MAX_TILE, n_frames: int = 8
) -> tuple[tuple[int, int], tuple[float, float], float]:
    """Tile size from the dominant spatial periodicity.

    Returns ``((th, tw), (period_y, period_x), strength)``: ``strength`` is the peak of the
    mean power spectrum over its median (beyond ~30 the texture is periodic and the tile
    is the smallest multiple of the period that is at least ``min_tile``; otherwise the
    tile is a quarter of the shorter frame side). Both are clamped to
    ``[min_tile, min(max_tile, 2/3 of the frame side)]``.

    Examples
    --------
    >>> x = np.arange(128)
    >>> img = (128 + 100 * np.sin(2 * np.pi * x / 16))[None, :].repeat(96, 0)
    >>> f = np.repeat(img[:, :, None], 3, axis=2).astype(np.uint8)[None].repeat(2, 0)
    >>> size, period, strength = tile_period(f, min_tile=40)
    >>> size[1], round(period[1])
    (48, 16)
    """
    t, h, w = frames.shape[:3]
    idx = np.linspace(0, t - 1, min(n_frames, t)).round().astype(int)
    g = _grey(frames[idx])
    g -= g.mean(axis=(1, 2), keepdims=True)
    win = np.hanning(h)[:, None] * np.hanning(w)[None, :]
    power = (np.abs(np.fft.fft2(g * win)) ** 2).mean(axis=0)
    fy = np.abs(np.fft.fftfreq(h))[:, None]
    fx = np.abs(np.fft.fftfreq(w))[None, :]
    # ignore periods longer than the largest tile (and DC)
    fmin = 1.0 / max(2, min(max_tile, max(h, w)))
    valid = np.maximum(fy, fx) >= fmin
    power = np.where(valid, power, 0.0)
    med = float(np.median(power[valid])) if valid.any() else 0.0
    k = int(np.argmax(power))
    ky, kx = divmod(k, w)
    strength = float(power.flat[k] / med) if med > 0 else 0.0
    py = 1.0 / fy[ky, 0] if fy[ky, 0] > 0 else float("inf")
    px = 1.0 / fx[0, kx] if fx[0, kx] > 0 else float("inf")
    default = max(min_tile, min(max_tile, (min(h, w) // 4) // 8 * 8))

    def size(period: float, side: int) -> int:
        hi = max(min_tile, min(max_tile, (2 * side) // 3))  # room for the overlap bands
        if strength >= 30 and np.isfinite(period) and period >= 2:
            m = int(np.ceil(min_tile / period))
            s = int(round(m * period))
            if s <= hi:
                return s
        return min(default, hi)

    return (size(py, h), size(px, w)), (float(py), float(px)), strength


# -- 2./3. temporal loop ---------------------------------------------------------------------
def _thumbs(frames: np.ndarray, side: int = 48) -> np.ndarray:
    t, h, w = frames.shape[:3]
    sy, sx = max(1, h // side), max(1, w // side)
    g = np.empty((t, h // sy, w // sx), np.float32)
    for i in range(0, t, 64):
        gg = _grey(frames[i : i + 64, : (h // sy) * sy, : (w // sx) * sx])
        g[i : i + 64] = gg.reshape(gg.shape[0], h // sy, sy, w // sx, sx).mean(axis=(2, 4))
    return g.reshape(t, -1)


def find_loop(
    frames: np.ndarray,
    *,
    min_loop: int,
    max_loop: int | None = None,
    transition: int = 8,
    length: int | None = None,
    prefer_long: float = 0.5,
) -> tuple[int, int, float]:
    """``(start, length, cost)`` of the best loop.

    ``cost`` is the mean RMS thumbnail difference between the frame sets
    ``start + j`` and ``start + length + j`` (``j < transition``) over the median
    consecutive-frame difference. With ``length`` given only the start is searched.
    """
    t = frames.shape[0]
    o = transition
    if length is not None:
        if t < length + o:
            raise InvalidArgumentError(
                f"clip has {t} frames, fewer than the loop length {length} plus the transition {o}"
            )
        lengths = [length]
    else:
        if t < min_loop + o:
            raise InvalidArgumentError(
                f"clip has {t} frames, fewer than the shortest loop: min_loop={min_loop} plus transition={o} frames"
            )
        hi = t - o if max_loop is None else min(max_loop, t - o)
        lengths = list(range(min_loop, hi + 1))
    th = _thumbs(frames)
    sq = (th * th).sum(axis=1)
    d = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2 * th @ th.T, 0) / th.shape[1])
    med = float(np.median(np.diag(d, 1))) or 1e-3
    lmax = max(lengths)
    best = (np.inf, 0, lengths[0], np.inf)
    for ln in lengths:
        n_start = t - ln - o + 1
        diag = np.diag(d, ln)  # d[i, i + ln]
        c = np.lib.stride_tricks.sliding_window_view(diag[: n_start + o - 1], o).mean(axis=1)[:n_start] / med
        s = int(np.argmin(c))
        score = float(c[s]) + prefer_long * (lmax - ln) / lmax
        if score < best[0]:
            best = (score, s, ln, float(c[s]))
    return best[1], best[2], best[3]


def transition_map(frames: np.ndarray, start: int, length: int, transition: int, *, sigma: float = 3.0) -> np.ndarray:
    """Per-pixel transition frame ``tau (H, W)`` in ``[0, transition)`` (see the module docstring)."""
    import cv2

    o = transition
    h, w = frames.shape[1:3]
    cost = np.empty((o, h, w), np.float32)
    for j in range(o):
        d = frames[start + length + j].astype(np.float32) - frames[start + j].astype(np.float32)
        cost[j] = cv2.GaussianBlur((d * d).sum(axis=2), (0, 0), sigma)
    return np.argmin(cost, axis=0).astype(np.int32)


def looped_block(
    frames: np.ndarray,
    start: int,
    length: int,
    tau: np.ndarray,
    y: int,
    x: int,
    h: int,
    w: int,
    u: Sequence[int] | None = None,
) -> np.ndarray:
    """Frames ``u`` (default all ``0..L-1``) of the seamless loop, block ``[y:y+h, x:x+w]``, uint8."""
    u = np.arange(length) if u is None else np.asarray(u)
    tb = tau[y : y + h, x : x + w]
    out = np.empty((len(u), h, w, frames.shape[3]), np.uint8)
    tmax = int(tb.max()) if tb.size else 0
    for i, uu in enumerate(u):
        early = frames[start + uu, y : y + h, x : x + w]
        if uu >= tmax:  # every pixel has passed its transition
            out[i] = early
        else:
            out[i] = np.where((uu < tb)[..., None], frames[start + length + uu, y : y + h, x : x + w], early)
    return out


# -- 4. optical flow -----------------------------------------------------------------------------
def flow_magnitude(frames: np.ndarray, start: int, length: int, *, pairs: int = 6, max_side: int = 320) -> np.ndarray:
    """Mean Farneback optical-flow magnitude ``(H, W)`` in full-resolution pixels per frame."""
    import cv2

    t, h, w = frames.shape[:3]
    scale = min(1.0, max_side / max(h, w))
    size = (max(8, int(round(w * scale))), max(8, int(round(h * scale))))
    acc = np.zeros((size[1], size[0]), np.float32)
    idx = np.linspace(start, start + length - 2, min(pairs, length - 1)).round().astype(int)
    for i in idx:
        a = cv2.resize(_grey(frames[i]), size, interpolation=cv2.INTER_AREA)
        b = cv2.resize(_grey(frames[i + 1]), size, interpolation=cv2.INTER_AREA)
        f = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 15, 3, 5, 1.2, 0)
        acc += np.sqrt((f * f).sum(axis=2))
    acc /= max(1, len(idx))
    return cv2.resize(acc, (w, h), interpolation=cv2.INTER_LINEAR) / scale


def _steps(flow_rows: np.ndarray, flow_gain: float) -> np.ndarray:
    return np.clip(1 + np.round(flow_gain * flow_rows), 1, MAX_STEP).astype(np.int64)


# -- 5. dynamic-programming cuts ---------------------------------------------------------------
def _dp(
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
    ``move``: see :func:`_dp`."""
    n, m = err.shape
    best = (np.inf, None)
    for c0 in range(m):
        start = np.zeros(m, bool)
        start[c0] = True
        e = err.copy()
        s0 = int(steps[0])
        far = np.abs(np.arange(m) - c0) > s0
        e[-1, far] = 1e30
        path, cost = _dp(e, steps, start, move)
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


def _sample(length: int, n: int) -> np.ndarray:
    return np.unique(np.linspace(0, length - 1, min(n, length)).round().astype(int))


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
    u = _sample(length, _SAMPLE_FRAMES)
    sub = block[u].astype(np.float32)
    flow = np.zeros((hb, wb), np.float32) if flow is None else flow
    # horizontal wrap: column x of the tile is block column x + tw left of the cut (continuing
    # the right edge), block column x from the cut on. Rows y and y + th share one cut.
    d = sub[:, :, tw : tw + bx] - sub[:, :, :bx]
    eh = (d * d).sum(axis=(0, 3)) / len(u)  # (hb, bx)
    e_rows = eh[:th].copy()
    e_rows[:by] += eh[th : th + by]
    e_rows[:, 0] = 1e30  # cut >= 1: column 0 continues column tw - 1
    steps = _steps(flow[:th, :bx].mean(axis=1), flow_gain)
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
    steps = _steps(flow[:by, :tw].mean(axis=0), flow_gain)
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
    u = _sample(length, _SAMPLE_FRAMES)
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
        path, cost = _dp(e, _steps(fl[:, :ring].mean(axis=1), flow_gain), None, move)
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
    e, move = _cut_cost(rt, it, ring, feather, _sample(length, _SAMPLE_FRAMES))
    fl = np.zeros((n, m), np.float32) if flow is None else _orient(flow, side, tile_axes=(0, 1))
    path, cost = circular_cut(e, _steps(fl[:, :ring].mean(axis=1), flow_gain), move)
    alpha = path_alpha(path, m, fade=feather + 1.0, start=1.0, lo=1, circular=True)
    weight = np.rint(255 * alpha).astype(np.uint8)
    a = (weight.astype(np.float32) / 255)[None, :, :, None]
    tile = np.rint(a * rt + (1 - a) * it.astype(np.float32)).astype(np.uint8)
    tile = np.ascontiguousarray(_unorient(tile, side, tile_axes=ax))
    weight = np.ascontiguousarray(_unorient(weight, side, tile_axes=(0, 1)))
    return tile, weight, cost


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
    u = _sample(length, _PRE_FRAMES)
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


# -- 6c. quilted torus ------------------------------------------------------------------------------
QUILT_MAX_RUN = 3  # blocks at most taken from one continuous piece of the clip, per direction
QUILT_MIN_PERIOD = 512  # the torus is at least this large (and twice the clip) in each direction
QUILT_MAX_PERIOD = 768  # ... but twice the clip only up to this
QUILT_MAX_LOOP = 64  # default longest loop of the quilted construction (the torus is stored whole)
_QUILT_FEATURE_FRAMES = 12
_QUILT_COMPONENTS = 8


def quilt_geometry(
    h: int, w: int, *, block: int | None = None, period: Sequence[int] | None = None
) -> tuple[int, int, tuple[int, int], tuple[int, int]]:
    """``(block, step, cell, period)`` of the quilted torus for an ``h x w`` clip.

    Blocks of ``block`` pixels (default a third of the shorter side rounded to 8, in 16..128) overlap
    by a quarter (``step = block - block // 4``); cells (the player's lattice, the stored
    tiles) are the fewest steps at least 64 pixels wide, so a 64-pixel run of the gather
    touches at most two cells; the period ``(py, px)`` is whole cells, at least 512 pixels
    (four clip sides for a clip under 128 pixels) and twice the clip up to 768 pixels in
    each direction (the torus is stored whole: 768 x 768 x 64 frames is 113 MB) (or
    ``period``, rounded up to whole cells).
    """
    if block is None:
        block = int(np.clip(round(min(h, w) / 3 / 8) * 8, 16, 128))
    block = check_int("block", block, 8)
    if block + 2 > min(h, w):
        raise InvalidArgumentError(f"quilt block {block} (plus 2) is larger than the clip frame {h}x{w}")
    step = block - block // 4
    cell = step * -(-64 // step)
    if period is None:
        want = (
            max(min(QUILT_MIN_PERIOD, 4 * h), min(2 * h, QUILT_MAX_PERIOD)),
            max(min(QUILT_MIN_PERIOD, 4 * w), min(2 * w, QUILT_MAX_PERIOD)),
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


def _block_alpha(err: np.ndarray, side: str, margin: int, fade: float) -> np.ndarray:
    """Share ``(B, B)`` of the new block across the minimum cut through the overlap band along
    ``side`` (``err``: the band's per-pixel error, across x for left/right): the cut, kept
    ``margin`` pixels from both edges of the band, smoothed (:func:`smooth_path`), and a
    cross-fade ``fade`` pixels wide centred on it (1 on the new block's side)."""
    from .quilt import min_cut_path

    err = np.array(err if side in ("left", "right") else err.T, np.float64)  # rows along the cut
    b, o = err.shape
    lo, hi = margin, max(margin + 1, o - margin)
    err[:, :lo], err[:, hi:] = 1e30, 1e30
    cut = min_cut_path(err)
    if side in ("left", "top"):  # the band's first pixel past the cut starts the new block
        alpha = 1.0 - path_alpha(cut, b, fade=fade, lo=lo, hi=hi)
    else:  # the band sits at the far edge: the new block is before the cut
        alpha = path_alpha(b - o + cut + 1, b, fade=fade, lo=b - o + lo, hi=b - o + hi)
    return alpha if side in ("left", "right") else alpha.T


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
    tx: _Texture,
    *,
    block: int | None = None,
    period: Sequence[int] | None = None,
    feather: int | None = None,
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
    frames. Each band ends at a minimum-error cut (summed over the loop) and the two sides
    cross-fade over ``feather`` pixels either side of the smoothed cut (:func:`path_alpha`;
    default a quarter of the overlap; the cut keeps that far from the band's edges). Since the bands wrap, the torus is
    seamless in x and y; each block loops seamlessly in t like the clip's loop.

    Returns ``(torus (L, py, px, 3) uint8, info)``.
    """
    from .quilt import block_errors

    f = tx.frames
    h, w = f.shape[1:3]
    b, step, _, (py, px) = quilt_geometry(h, w, block=block, period=period)
    o = b - step
    fe = max(1, o // 4) if feather is None else check_int("feather", feather, 0)
    fe = min(fe, (o - 1) // 2)
    nby, nbx = py // step, px // step
    length = tx.length
    rng = np.random.default_rng(seed)
    u_feat = _sample(length, _QUILT_FEATURE_FRAMES)
    u_cut = _sample(length, 16)
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
            rows = (i * step + np.arange(b)) % py
            cols = (j * step + np.arange(b)) % px
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
                torus[:, rows[:, None], cols[None, :]] = tx.block(y0, x0, b, b)
                src[i, j] = (y0, x0)
                if step_done:
                    step_done()
                continue
            old_feat = torus[u_feat[:, None, None], rows[None, :, None], cols[None, None, :]].astype(np.float32)
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
            old = torus[:, rows[:, None], cols[None, :]]
            d = new[u_cut].astype(np.float32) - old[u_cut].astype(np.float32)
            perr = (d * d).sum(axis=(0, 3)) / len(u_cut)
            band = {"left": perr[:, :o], "right": perr[:, b - o :], "top": perr[:o, :], "bottom": perr[b - o :, :]}
            alpha = np.ones((b, b))
            for s in sides:
                alpha = np.minimum(alpha, _block_alpha(band[s], s, fe + 1, 2.0 * fe + 1.0))
            keep = alpha >= 0.5
            costs.append(float(perr[mask & keep].mean()) if (mask & keep).any() else 0.0)
            a = alpha.astype(np.float32)[None, :, :, None]
            torus[:, rows[:, None], cols[None, :]] = np.rint(a * new + (1 - a) * old).astype(np.uint8)
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


# -- 9. spatial stationarity ---------------------------------------------------------------------
_STAT_OFFSETS = np.array([16.0, 4.0, 1.0])  # grey levels added to each statistic's median


def stationarity(frames: np.ndarray, *, grid: int = 4, n_frames: int = 48) -> tuple[float, dict]:
    """How alike the parts of each frame are: ``(figure, details)``, figure in (0, 1].

    Each of up to ``n_frames`` frames is split into ``grid x grid`` windows; per window its
    mean luma, its luma contrast (standard deviation) and its activity (mean absolute change
    to the next frame). Per statistic and frame, the most unusual window's excess over the
    median window, relative to the median (plus 16, 4 and 1 grey levels, so flat statistics
    do not divide by zero): a texture has every window alike, a single object on a plain
    background has one window unlike the rest. The median over frames of the largest of the
    three excesses is ``spread``; the figure is ``1 / (1 + spread)``. Below
    :data:`STATIONARITY_WARN` (spread above 1) the clip is not a texture all over, and tiles
    cut from it repeat or misplace its structures (grass 0.74, sea 0.65; a moving disc on a
    plain background 0.32; a pendulum clock 0.20).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> noise = rng.integers(0, 256, (6, 64, 64, 3)).astype(np.uint8)
    >>> stationarity(noise)[0] > 0.8
    True
    >>> still = np.full((6, 64, 64, 3), 90, np.uint8); still[:, 5:15, 5:15] = 250
    >>> stationarity(still)[0] < STATIONARITY_WARN
    True
    """
    t, h, w = frames.shape[:3]
    idx = np.unique(np.linspace(0, max(0, t - 2), min(max(1, t - 1), n_frames)).round().astype(int))
    nxt = np.minimum(idx + 1, t - 1)
    g = _grey(frames[idx])
    act = np.abs(_grey(frames[nxt]) - g)
    ys = np.linspace(0, h, grid + 1).astype(int)
    xs = np.linspace(0, w, grid + 1).astype(int)
    stats = np.empty((grid * grid, 3, len(idx)))
    for i in range(grid):
        for j in range(grid):
            win = g[:, ys[i] : ys[i + 1], xs[j] : xs[j + 1]]
            k = i * grid + j
            stats[k, 0] = win.mean(axis=(1, 2))
            stats[k, 1] = win.std(axis=(1, 2))
            stats[k, 2] = act[:, ys[i] : ys[i + 1], xs[j] : xs[j + 1]].mean(axis=(1, 2))
    med = np.median(stats, axis=0)
    excess = np.abs(stats - med).max(axis=0) / (med + _STAT_OFFSETS[:, None])
    per_stat = np.median(excess, axis=1)
    spread = float(per_stat.max())
    names = ("brightness", "contrast", "activity")
    return 1.0 / (1.0 + spread), {
        "spread": spread,
        "worst": names[int(np.argmax(per_stat))],
        **{f"spread_{n}": float(v) for n, v in zip(names, per_stat)},
    }


# -- 8. colour statistics --------------------------------------------------------------------------
def colour_stats(tile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean RGB (0..255) and mean HSV (hue in degrees by circular mean, S and V in 0..1) of a tile."""
    import cv2

    u = _sample(tile.shape[0], 16)
    rgb = tile[u].reshape(-1, 1, 3)
    mean_rgb = rgb.reshape(-1, 3).mean(axis=0, dtype=np.float64)
    hsv = cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2HSV).reshape(-1, 3).astype(np.float64)
    ang = np.deg2rad(hsv[:, 0])
    hue = float(np.rad2deg(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())) % 360.0)
    return mean_rgb, np.array([hue, hsv[:, 1].mean(), hsv[:, 2].mean()])


# -- the whole analysis -------------------------------------------------------------------------------
class _Texture:
    """One class's loop, flow and primary tile."""

    def __init__(self, frames, start, length, cost, tau, flow):
        self.frames, self.start, self.length, self.cost, self.tau, self.flow = frames, start, length, cost, tau, flow
        self.primary = None
        self.primary_pos = (0, 0)
        self.toroid_cost = (0.0, 0.0)
        self._activity = None

    def block(self, y, x, h, w, u=None):
        return looped_block(self.frames, self.start, self.length, self.tau, y, x, h, w, u)

    @property
    def activity(self) -> np.ndarray:
        """Mean squared consecutive-frame difference per pixel over the loop (a few pairs; once)."""
        if self._activity is None:
            f = self.frames
            idx = _sample(self.length - 1, 8) + self.start
            acc = np.zeros(f.shape[1:3], np.float32)
            for i in idx:
                d = f[i + 1].astype(np.float32) - f[i].astype(np.float32)
                acc += (d * d).sum(axis=2)
            self._activity = acc / len(idx)
        return self._activity


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
    main = _frames("clip", clip)
    extra = [_frames(f"mix[{i}]", c) for i, c in enumerate(mix)]
    names = list(names) if names is not None else ["main"] + [f"mix{i + 1}" for i in range(len(extra))]
    if len(names) != 1 + len(extra):
        raise InvalidArgumentError(f"names must name {1 + len(extra)} textures, not {len(names)}")
    if not (isinstance(flow_gain, (int, float)) and 0 <= flow_gain <= 10):
        raise InvalidArgumentError(f"flow_gain must be a number in [0, 10], not {flow_gain!r}")
    if construction is None:  # ring options name the ring construction
        construction = "ring" if extra or n_tiles is not None or ring is not None else "quilted"
    if construction not in CONSTRUCTIONS:
        raise InvalidArgumentError(f"construction must be one of {CONSTRUCTIONS}, not {construction!r}")
    if construction == "quilted":
        if extra:
            raise InvalidArgumentError(
                "construction 'quilted' cannot mix textures: border tiles need every class's "
                "shared ring (construction='ring')"
            )
        if n_tiles is not None:
            raise InvalidArgumentError(
                "n_tiles applies to construction 'ring' only; the quilted torus has as many cells as its period holds"
            )
        return _learn_quilted(
            main,
            names,
            tile=tile,
            min_loop=min_loop,
            max_loop=max_loop,
            transition=transition,
            period=period,
            seed=seed,
            progress=progress,
        )
    if period is not None:
        raise InvalidArgumentError(f"period applies to construction 'quilted' only, not {construction!r}")
    if construction == "wang" and extra:
        raise InvalidArgumentError(
            "construction 'wang' cannot mix textures: border tiles need every class's shared ring (construction='ring')"
        )
    if construction == "wang" and n_tiles is not None:
        raise InvalidArgumentError(
            f"n_tiles applies to construction 'ring' only; the Wang set has edge_colours ** 3 = {edge_colours**3} tiles"
        )
    n_tiles = check_int("n_tiles", 4 if n_tiles is None else n_tiles, 1, 64)
    edge_colours = check_int("edge_colours", edge_colours, 2, 4)
    n_own = edge_colours**3 if construction == "wang" else n_tiles
    min_loop = check_int("min_loop", min_loop, 2)
    transition = check_int("transition", transition, 1)
    if max_loop is not None:
        max_loop = check_int("max_loop", max_loop, min_loop)
    if transition >= min_loop:
        raise InvalidArgumentError(f"transition ({transition}) must be smaller than min_loop ({min_loop})")
    if not (isinstance(flow_gain, (int, float)) and 0 <= flow_gain <= 10):
        raise InvalidArgumentError(f"flow_gain must be a number in [0, 10], not {flow_gain!r}")
    min_tile = check_int("min_tile", min_tile, 8)
    max_tile = check_int("max_tile", max_tile, min_tile)
    total = 6 + n_own + len(extra) * (3 + n_tiles) + (len(extra) + 1) * len(extra)
    done = 0

    def step(k: int = 1) -> None:
        nonlocal done
        done += k
        if progress is not None:
            progress(min(done, total), total)

    t, h, w = main.shape[:3]
    if tile is None:
        (th, tw), period, strength = tile_period(main, min_tile=min_tile, max_tile=max_tile)
        for f in extra:
            th, tw = min(th, f.shape[1] // 2), min(tw, f.shape[2] // 2)
    else:
        try:
            th, tw = (int(tile), int(tile)) if isinstance(tile, (int, np.integer)) else (int(v) for v in tile)
        except (TypeError, ValueError):
            raise InvalidArgumentError(f"tile must be an integer or (th, tw), not {tile!r}") from None
        if th < 8 or tw < 8:
            raise InvalidArgumentError(f"tile must be at least 8x8, not {th}x{tw}")
        period, strength = (0.0, 0.0), 0.0  # not measured: the caller chose the size
    step()
    for label, f in [("clip", main)] + [(f"mix[{i}]", e) for i, e in enumerate(extra)]:
        if th + 2 > f.shape[1] or tw + 2 > f.shape[2]:
            raise InvalidArgumentError(
                f"tile {th}x{tw} (plus a 2-pixel overlap) is larger than the {label} frame {f.shape[1]}x{f.shape[2]}"
            )

    start, length, loop_cost = find_loop(main, min_loop=min_loop, max_loop=max_loop, transition=transition)
    step()
    textures = [
        _Texture(
            main,
            start,
            length,
            loop_cost,
            transition_map(main, start, length, transition),
            flow_magnitude(main, start, length),
        )
    ]
    step()
    for f in extra:
        s, _, c = find_loop(f, min_loop=min_loop, transition=transition, length=length)
        textures.append(
            _Texture(f, s, length, c, transition_map(f, s, length, transition), flow_magnitude(f, s, length))
        )
        step()
    mean_flow = float(np.mean([tx.flow.mean() for tx in textures]))
    if overlap is None:
        b = max(2, min(th, tw) // 4) + int(round(2 * mean_flow))
    else:
        b = check_int("overlap", overlap, 2)
    by = max(2, min(b, h - th, *(f.shape[1] - th for f in extra)))
    bx = max(2, min(b, w - tw, *(f.shape[2] - tw for f in extra)))
    # a narrow ring: every tile of a class repeats it, so it is the only periodic content
    r = max(2, min(th, tw) // 10) if ring is None else check_int("ring", ring, 2)
    if r > min(th, tw) // 2 - 1:
        raise InvalidArgumentError(f"ring must be at most {min(th, tw) // 2 - 1} for a {th}x{tw} tile, not {r}")
    fe = max(r, min(th, tw) // 5) if feather is None else check_int("feather", feather, 0)
    fe = min(fe, min(th, tw) // 2 - 1 - r)
    # border cuts may run deeper than the ring (the strip is the other class's toroidal
    # primary, which continues its own cells at any depth), as deep as leaves the fade
    # short of the tile centre: more room for a quiet path (grass|water, 250 frames, at
    # the cut: 1.6x the inside seams with depth 2 * ring, 1.15x with this)
    depth = max(r, min(th, tw) // 2 - 1 - fe)

    tiles, tcls, rcls, masks, costs = [], [], [], [], []
    edges = None  # ring sets: the model's default, no colours
    if construction == "wang":
        step()
        wang, edges, strip_depth = _wang_tiles(textures[0], th, tw, r, edge_colours, flow_gain, step)
        for tile_k, mask, cost in wang:
            tiles.append(tile_k), tcls.append(0), rcls.append(0), masks.append(mask), costs.append(cost)
    else:
        # primary toroidal tile of every class, then tiles sharing its ring
        for tx in textures:
            tx.primary, tx.primary_pos, tx.toroid_cost = _primary(tx, th, tw, by, bx, flow_gain)
            step()
        for ci, tx in enumerate(textures):
            tiles.append(tx.primary)
            tcls.append(ci), rcls.append(ci), masks.append(np.full((th, tw), 255, np.uint8)), costs.append(0.0)
            for tile_k, mask, cost in _interiors(
                tx, [tx.primary] * (n_tiles - 1), th, tw, r, flow_gain, step, taken=[tx.primary_pos]
            ):
                tiles.append(tile_k), tcls.append(ci), rcls.append(ci), masks.append(mask), costs.append(cost)
    step()
    # border tiles: a strip of class c's primary along one side of class a's primary
    sides = [-1] * len(tiles)
    for a, ta in enumerate(textures):
        for c, tc in enumerate(textures):
            if a == c:
                continue
            for si, side in enumerate(SIDES):
                tile_k, mask, cost = side_join(tc.primary, ta.primary, depth, side, feather=fe, flow_gain=flow_gain)
                tiles.append(tile_k), tcls.append(a), rcls.append(c), masks.append(mask), costs.append(cost)
                sides.append(si)
            step()
    stats = [colour_stats(tl) for tl in tiles]
    step()
    wang_info = {"edge_colours": edge_colours, "strip_depth": strip_depth} if construction == "wang" else {}
    model = TilesModel(
        tiles=np.stack(tiles),
        tile_class=np.array(tcls, np.int32),
        ring_class=np.array(rcls, np.int32),
        masks=np.stack(masks),
        border_side=np.array(sides, np.int8),
        seam_cost=np.array(costs),
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
            **_stationarity_info(main),
            "tile_h": th,
            "tile_w": tw,
            "loop_length": length,
            "transition": transition,
            "overlap_y": by,
            "overlap_x": bx,
            "ring": r,
            "feather": fe,
            "border_depth": depth,
            "ring_feather": _ring_feather(r, th, tw),
            "period_y": period[0],
            "period_x": period[1],
            "periodicity": strength,
            "mean_flow": mean_flow,
            "flow_gain": float(flow_gain),
            "source_frames": t,
            "n_classes": len(textures),
            "median_frame_step": _median_step(main),
        },
    )
    step(total)
    return model


def _stationarity_info(frames: np.ndarray) -> dict:
    figure, details = stationarity(frames)
    return {"stationarity": figure, "stationarity_worst": details["worst"]}


def _learn_quilted(
    main: np.ndarray,
    names: list[str],
    *,
    tile,
    min_loop: int,
    max_loop: int | None,
    transition: int,
    period,
    seed: int,
    progress: Progress | None,
) -> TilesModel:
    """The quilted construction of :func:`learn_tiles` (one texture)."""
    min_loop = check_int("min_loop", min_loop, 2)
    transition = check_int("transition", transition, 1)
    max_loop = max(min_loop, QUILT_MAX_LOOP) if max_loop is None else check_int("max_loop", max_loop, min_loop)
    if transition >= min_loop:
        raise InvalidArgumentError(f"transition ({transition}) must be smaller than min_loop ({min_loop})")
    seed = check_int("seed", seed, 0)
    block = None
    if tile is not None:
        if not isinstance(tile, (int, np.integer)) or isinstance(tile, bool):
            raise InvalidArgumentError(
                f"tile must be an integer (the quilt block size of construction 'quilted'), not {tile!r}"
            )
        block = int(tile)
    t, h, w = main.shape[:3]
    b, step, cell, (py, px) = quilt_geometry(h, w, block=block, period=period)
    total = 4 + (py // step) * (px // step)
    done = 0

    def step_done(k: int = 1) -> None:
        nonlocal done
        done += k
        if progress is not None:
            progress(min(done, total), total)

    start, length, loop_cost = find_loop(main, min_loop=min_loop, max_loop=max_loop, transition=transition)
    tx = _Texture(
        main,
        start,
        length,
        loop_cost,
        transition_map(main, start, length, transition),
        np.zeros(main.shape[1:3], np.float32),
    )
    step_done(2)
    torus, qinfo = quilted_torus(tx, block=b, period=(py, px), seed=seed, step_done=step_done)
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
            **_stationarity_info(main),
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
            "median_frame_step": _median_step(main),
        },
    )
    step_done(total)
    return model


def _primary(tx: _Texture, th: int, tw: int, by: int, bx: int, flow_gain: float):
    """Best toroidal tile of one texture: rank positions by a cheap bound, cut the best three."""
    f = tx.frames
    h, w = f.shape[1:3]
    hb, wb = th + by, tw + bx
    stride_y, stride_x = max(4, th // 4), max(4, tw // 4)
    ys, xs = _starts(h, hb, stride_y), _starts(w, wb, stride_x)
    u = _sample(tx.length, _PRE_FRAMES)
    act = tx.activity
    ranked = []
    for y in ys:
        for x in xs:
            blk = tx.block(y, x, hb, wb, u).astype(np.float32)
            dh = blk[:, :th, tw : tw + bx] - blk[:, :th, :bx]
            dv = blk[:, th : th + by, :tw] - blk[:, :by, :tw]
            bound = (dh * dh).sum(axis=(0, 3)).min(axis=1).mean() + (dv * dv).sum(axis=(0, 3)).min(axis=0).mean()
            ranked.append((float(bound), int(y), int(x), float(act[y : y + hb, x : x + wb].mean())))
    ranked = _lively(ranked)
    best = None
    for _, y, x, _ in ranked[:3]:
        tile, ch, cv = toroidal_tile(
            tx.block(y, x, hb, wb), th, tw, flow=tx.flow[y : y + hb, x : x + wb], flow_gain=flow_gain
        )
        if best is None or ch + cv < best[2][0] + best[2][1]:
            best = (tile, (y, x), (ch, cv))
    return best


def _interiors(
    tx: _Texture,
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
    rf = _ring_feather(r, th, tw)
    f = tx.frames
    h, w = f.shape[1:3]
    u = _sample(tx.length, _PRE_FRAMES)
    ringmask = np.ones((th, tw), bool)
    ringmask[r : th - r, r : tw - r] = False
    stride_y, stride_x = max(4, th // 4), max(4, tw // 4)
    places = [(int(y), int(x)) for y in _starts(h, th, stride_y) for x in _starts(w, tw, stride_x)]
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
            ranked, ranked_for = _lively(ranked), ring_tile
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


def _ring_feather(r: int, th: int, tw: int) -> int:
    return min(max(2, r // 2), min(th, tw) // 2 - 1 - r)


def _wang_tiles(tx: _Texture, th: int, tw: int, r: int, colours: int, flow_gain: float, step, seed: int = 0):
    """The stochastic Wang set of one texture (:func:`wang_edges`).

    Edge strips: ``colours`` horizontal and ``colours`` vertical pieces of the looped clip at
    typical places apart from each other, each ``2 depth`` pixels across its edge (``depth``
    = the ring plus its feathering, as far as a ring cut and its fade reach). A tile's ring
    is the inner halves of its four strips (:func:`wang_ring`), joined to an interior from
    yet another place by the ring cuts (:func:`ring_join`).
    """
    d = r + _ring_feather(r, th, tw) + 1
    f = tx.frames
    h, w = f.shape[1:3]
    act = tx.activity
    grad = np.zeros((h, w), np.float32)
    for i in _sample(tx.length, 8) + tx.start:
        g = _grey(f[i : i + 1])[0]
        grad[:, 1:] += np.diff(g, axis=1) ** 2
        grad[1:] += np.diff(g, axis=0) ** 2
    rng = np.random.default_rng(seed)

    typical: dict[tuple[int, int], list[tuple[int, int]]] = {}  # per strip shape, scored once

    def places(bh: int, bw: int) -> list[tuple[int, int]]:
        """Typical places first: spatial and temporal activity near the clip's median (a strip
        livelier or calmer than the rest would mark every edge it sits on), shuffled."""
        if (bh, bw) not in typical:
            ys, xs = _starts(h, bh, max(2, bh // 4)), _starts(w, bw, max(2, bw // 4))
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
    tiles = _interiors(tx, rings, th, tw, r, flow_gain, step, taken=[(y, x) for y, x, _, _ in taken])
    return tiles, edges, d


def _starts(extent: int, size: int, stride: int) -> np.ndarray:
    """Block starts every ``stride`` pixels along an axis of ``extent``, the last flush with its end."""
    return np.unique(np.r_[np.arange(0, extent - size + 1, stride), extent - size])


def _lively(ranked: list) -> list:
    """Candidates sorted by cost, the calm ones (activity below half the median) last.

    Without this the lowest overlap error wins in the stillest part of the clip, and the
    tiles would show a texture calmer than the source.
    """
    med = float(np.median([r[3] for r in ranked]))
    return sorted(ranked, key=lambda r: (r[3] < 0.5 * med, r[0]))


def _median_step(frames: np.ndarray) -> float:
    n = min(frames.shape[0] - 1, 64)
    idx = np.linspace(0, frames.shape[0] - 2, n).round().astype(int)
    d = frames[idx + 1].astype(np.float32) - frames[idx].astype(np.float32)
    return float(np.median(np.sqrt((d * d).mean(axis=(1, 2, 3)))))


def _frames(name: str, clip: Clip | np.ndarray) -> np.ndarray:
    frames = clip.frames if isinstance(clip, Clip) else np.asarray(clip)
    if frames.ndim != 4 or frames.dtype != np.uint8 or frames.shape[3] not in (1, 3):
        raise InvalidArgumentError(
            f"{name} must be (T, H, W, C) uint8 frames with C 1 or 3, not {frames.dtype} {frames.shape}"
        )
    if frames.shape[3] == 1:
        frames = np.repeat(frames, 3, axis=3)
    return frames
