"""Video textures with turn points (Van Haevre & Van Reeth) and classic transitions (Schoedl et al.).

Analysis, all on a ``T x T`` matrix of frame distances computed on reduced frames:

1. Symmetry per frame (the seed's eq. 2): ``Sym_i = sum_r C(2(n-s), n-r) D[i-r, i+r]``,
   ``r = 1..n``. Read literally the weights peak at ``r = s`` (for ``s = 0`` they fall from
   ``r = 1`` outward) and a larger ``s`` flattens them (``w_1 / w_n = C(2(n-s), n-1)``), the
   opposite of what the seed's prose says; we implement the formula. Frames closer than
   ``n`` to an end use the mirrored pairs that fit (at least ``min_pairs``), normalised by
   the weights used, so turns near the clip's ends can be found (``min_pairs = n`` is the
   seed exactly: only full windows).
2. Normalisation (eq. 3) ``sym = 1 - Sym / Sym_max``, local maxima within ``r`` (eq. 4),
   maxima below ``min_symmetry`` dropped, ``p_max = sym / 2`` (eq. 5) and 1 at the
   outermost turn points.
3. Transitions: the distance matrix filtered along its diagonals with binomial weights
   (``2 m`` taps) so a jump also matches the neighbouring frames (dynamics preserved), the
   future-cost iteration ``F_ij = C_ij^p + alpha min_k F_jk`` (continuing costs nothing but
   leads on; the last frame is a dead end), probabilities ``exp(-F / sigma)``, and only
   transitions that are local minima of ``F`` and probable enough kept. Forward-only play
   always jumps at ``exit_frame`` so it never runs off the end.
4. No double images: a jump whose crossfade (the player's default, ``CROSSFADE`` frames,
   played forward and mirrored backward) would show the moving parts twice is not taken:
   every crossfaded frame must be within ``max_ghost`` times the source's own level of
   :func:`~dynatex.analyzer.metrics.double_image` (that of the mean of two consecutive frames).
   With ``warp`` on, a jump whose plain crossfade fails is measured again motion-compensated
   (both frames warped along their optical flow, :mod:`~dynatex.analyzer.flow`): the better
   counts, and the flows of the jumps whose warp is better are stored for the player.
"""

from __future__ import annotations

import math

import numpy as np

from ..checks import check_int
from ..errors import InvalidArgumentError
from ..tiledb.turnpoints import TurnPointModel
from .flow import PairFlows, can_flow, crossfade_pairs, warped_crossfade_ghost
from .lds import _stepper
from .methods import check_params
from .metrics import DoubleImages
from .video import Clip, Progress, clip_frames

#: Frames of the crossfade a jump is checked with (the player's default ``crossfade``).
CROSSFADE = 4
#: A jump whose plain crossfade shows more than this many times the allowed double images is not
#: tried warped: the warp halves a clock pendulum's at best, and each try costs optical flows.
WARP_HOPE = 2.0
#: Most jumps an analysis tries warped (of those the search asks about first, the nearest to
#: passing first); the flows of one cost about a second on a 352x288 clip.
MAX_WARP_TRIES = 48
#: Rounds of refusing double-image jumps and looking again for the locally best ones.
MAX_GHOST_ROUNDS = 6


def frame_features(frames: np.ndarray, size: int = 64) -> np.ndarray:
    """Frames reduced for distance computations: area-downscaled so the longer side is at most
    ``size``, as float32 rows ``(T, h * w * C)``, scaled so distances approximate full-resolution L2.

    Examples
    --------
    >>> f = frame_features(np.zeros((3, 128, 64, 3), np.uint8), size=32)
    >>> f.shape
    (3, 1536)
    """
    frames = clip_frames(frames)
    size = _int("feature_size", size, 4)
    t, h, w, c = frames.shape
    factor = max(h, w) / size
    if factor <= 1:
        return frames.reshape(t, -1).astype(np.float32)
    import cv2

    nh, nw = max(1, round(h / factor)), max(1, round(w / factor))
    out = np.empty((t, nh * nw * c), np.float32)
    for i in range(t):
        small = cv2.resize(frames[i], (nw, nh), interpolation=cv2.INTER_AREA).astype(np.float32)
        out[i] = small.reshape(-1)
    # Each reduced pixel stands for (h*w)/(nh*nw) pixels: scale to keep distances comparable.
    out *= math.sqrt((h * w) / (nh * nw))
    return out


def distance_matrix(features: np.ndarray) -> np.ndarray:
    """Euclidean distances between all rows, ``(T, T)`` float64, exactly symmetric with a zero diagonal."""
    x = np.asarray(features, np.float64)
    g = x @ x.T
    sq = np.diag(g).copy()
    d2 = sq[:, None] + sq[None, :] - 2 * g
    np.maximum(d2, 0, out=d2)
    d = np.sqrt(d2)
    d = 0.5 * (d + d.T)
    np.fill_diagonal(d, 0.0)
    return d


def symmetry_weights(n: int, s: int) -> np.ndarray:
    """Binomial weights ``C(2(n-s), n-r)`` for ``r = 1..n`` (the seed's eq. 2).

    Examples
    --------
    >>> symmetry_weights(4, 1).tolist()
    [20.0, 15.0, 6.0, 1.0]
    """
    return np.array([math.comb(2 * (n - s), n - r) for r in range(1, n + 1)], np.float64)


def symmetry_scores(d: np.ndarray, *, n: int, s: int, min_pairs: int) -> tuple[np.ndarray, np.ndarray]:
    """Raw weighted mirrored distances (eq. 2) and the normalised symmetry (eq. 3).

    Returns ``(sym_raw, symmetry)``, both ``(T,)``; frames with fewer than ``min_pairs``
    mirrored pairs on both sides get ``sym_raw = 0`` and ``symmetry = 0``.
    """
    t = d.shape[0]
    w = symmetry_weights(n, s)
    raw = np.zeros(t)
    wsum = np.zeros(t)
    idx = np.arange(t)
    for r in range(1, n + 1):
        ok = (idx - r >= 0) & (idx + r < t)
        i = idx[ok]
        raw[i] += w[r - 1] * d[i - r, i + r]
        wsum[i] += w[r - 1]
    pairs = np.minimum(idx, t - 1 - idx).clip(max=n)
    valid = pairs >= min_pairs
    raw = np.where(valid, raw / np.where(wsum > 0, wsum, 1) * w.sum(), 0.0)
    sym = np.zeros(t)
    top = raw[valid].max() if valid.any() else 0.0
    if top > 0:
        sym[valid] = 1.0 - raw[valid] / top
    elif valid.any():
        sym[valid] = 1.0  # a constant clip: every frame mirrors perfectly
    return raw, sym


def local_maxima(values: np.ndarray, r: int) -> np.ndarray:
    """Eq. 4: ``values`` kept where it is the maximum of ``values[i-r .. i+r]`` (first of ties), else 0."""
    t = values.shape[0]
    out = np.zeros(t)
    for i in range(t):
        v = values[i]
        if v <= 0:
            continue
        lo, hi = max(0, i - r), min(t, i + r + 1)
        if v >= values[lo:hi].max() and not np.any(values[lo:i] == v):
            out[i] = v
    return out


def filtered_distances(d: np.ndarray, taps: int) -> np.ndarray:
    """``D'[i, j] = sum_k w_k D[i+k, j+k]`` for ``k = -taps .. taps-1`` with binomial weights
    (normalised to sum 1); ``inf`` where the window leaves the clip."""
    t = d.shape[0]
    w = np.array([math.comb(2 * taps - 1, k) for k in range(2 * taps)], np.float64)
    w /= w.sum()
    out = np.full((t, t), np.inf)
    lo, hi = taps, t - taps + 1  # i + k must stay in [0, t) for k in [-taps, taps-1]
    if hi <= lo:
        return out
    acc = np.zeros((hi - lo, hi - lo))
    for k, wk in zip(range(-taps, taps), w):
        acc += wk * d[lo + k : hi + k, lo + k : hi + k]
    out[lo:hi, lo:hi] = acc
    return out


def future_costs(cost_p: np.ndarray, alpha: float, dead: float, max_iter: int = 10000) -> tuple[np.ndarray, np.ndarray]:
    """Q-learning iteration for forward play: ``F[i, j] = cost_p[i, j] + alpha * m[j]`` with
    ``m[j] = min(alpha * m[j + 1], min_k F[j, k])`` (continuing is free but leads on) and the
    last frame, which cannot continue, worth ``dead`` plus its best jump.

    Returns ``(F, m)``.
    """
    t = cost_p.shape[0]
    m = np.zeros(t)
    m[-1] = dead
    # Continuing chains are solved exactly in each sweep: m[j] = min_{k >= j} alpha^(k-j) b[k]
    # (b = best jump, capped by the dead end at the last frame), a reversed running minimum
    # of alpha^k b[k]; only chains of jumps need further sweeps.
    powers = alpha ** np.arange(t, dtype=np.float64)
    for _ in range(max_iter):
        b = np.minimum((cost_p + alpha * m[None, :]).min(axis=1), dead)
        new = np.minimum.accumulate((powers * b)[::-1])[::-1] / powers
        np.minimum(new, dead, out=new)
        if np.allclose(new, m, rtol=1e-10, atol=1e-10 * dead):
            m = new
            break
        m = new
    return cost_p + alpha * m[None, :], m


def learn_turnpoints(
    clip: Clip | np.ndarray,
    *,
    n: int = 4,
    s: int = 1,
    r: int = 4,
    min_pairs: int = 2,
    min_symmetry: float = 0.3,
    feature_size: int = 64,
    taps: int = 2,
    p: float = 2.0,
    alpha: float = 0.999,
    sigma: float = 0.1,
    min_gap: int = 6,
    min_prob: float = 0.02,
    max_per_frame: int = 3,
    max_cost: float = 2.0,
    max_ghost: float = 1.0,
    warp: str = "on",
    progress: Progress | None = None,
) -> TurnPointModel:
    """Find turn points and transitions of a clip (the ``turnpoints`` method).

    Parameters
    ----------
    clip : Clip or ndarray
        Frames ``(T, H, W, C)`` uint8; ``T >= 2 n + 1``.
    n : int
        Mirrored frame pairs in the symmetry test (eq. 2), ``n >= 1``.
    s : int
        Smoothness of the binomial weights, ``0 <= s < n / 2``.
    r : int
        Range of the local-maximum reduction (eq. 4): turn points are more than ``r`` apart.
    min_pairs : int
        Fewest mirrored pairs a frame near the clip's ends needs to be scored, ``1..n``.
    min_symmetry : float
        Local maxima below this normalised symmetry (in [0, 1)) are not turn points.
    feature_size : int
        Frames are area-downscaled to this longer side before distances (see ``info``
        ``distance_correlation`` for the agreement with full-resolution L2).
    taps : int
        Half-length of the diagonal filter of the transition costs (``2 taps`` frames).
    p : float
        Exponent on the filtered cost (Schoedl's ``p``), ``> 0``.
    alpha : float
        Future-cost discount, in (0, 1).
    sigma : float
        Probability scale as a fraction of the mean finite cost: ``prob ~ exp(-F / sigma)``.
    min_gap : int
        Transitions to within ``min_gap`` frames of the natural successor are dropped (short
        jumps near a slow turn look like stutters and add little variety).
    min_prob : float
        Transitions less probable than this per visit are dropped.
    max_per_frame : int
        Most transitions kept per source frame (the best ones).
    max_cost : float
        Transitions whose filtered cost exceeds ``max_cost`` times the median distance
        between consecutive frames are dropped (visibly wrong jumps), ``> 0``.
    max_ghost : float
        Transitions whose crossfade shows double images beyond ``max_ghost`` times the source's
        own level (:func:`~dynatex.analyzer.metrics.double_image_level`) are not taken; 0 keeps
        them all (no check).
    warp : {"on", "off"}
        ``on``: a jump whose plain crossfade shows double images beyond ``max_ghost`` is measured
        motion-compensated, and kept with its pairs' optical flow stored where that passes;
        ``off``: plain crossfades only. With ``max_ghost`` 0 every kept jump is warped. Frames
        too small for a flow (:func:`~dynatex.analyzer.flow.can_flow`) are not warped.
    progress : callable(done, total), optional
        Called after each of the 4 stages.

    Returns
    -------
    TurnPointModel

    Examples
    --------
    >>> t = np.arange(60)
    >>> x = (20 + 10 * np.cos(2 * np.pi * t / 20)).round().astype(int)   # extremes at 0, 10, 20, ...
    >>> frames = np.zeros((60, 8, 48, 3), np.uint8)
    >>> for i, xi in enumerate(x):
    ...     frames[i, :, xi - 2:xi + 2] = 255
    >>> model = learn_turnpoints(frames, n=3, s=1, r=4)
    >>> model.turn_points.tolist()
    [10, 20, 30, 40, 50]
    """
    frames = clip_frames(clip)
    t = frames.shape[0]
    (
        n,
        s,
        r,
        min_symmetry,
        max_cost,
        max_ghost,
        warp,
        min_pairs,
        feature_size,
        taps,
        p,
        alpha,
        sigma,
        min_gap,
        min_prob,
        max_per_frame,
    ) = check_params(
        "turnpoints",
        n=n,
        s=s,
        r=r,
        min_symmetry=min_symmetry,
        max_cost=max_cost,
        max_ghost=max_ghost,
        warp=warp,
        min_pairs=min_pairs,
        feature_size=feature_size,
        taps=taps,
        p=p,
        alpha=alpha,
        sigma=sigma,
        min_gap=min_gap,
        min_prob=min_prob,
        max_per_frame=max_per_frame,
    )
    if not s < n / 2:
        raise InvalidArgumentError(f"s must satisfy 0 <= s < n/2 (the seed's eq. 2), got s={s} with n={n}")
    if min_pairs > n:
        raise InvalidArgumentError(f"min_pairs must be in 1..n={n}, not {min_pairs}")
    if t < 2 * n + 1:
        raise InvalidArgumentError(
            f"clip has {t} frames, too short for n={n}: the symmetry test needs at least "
            f"2n+1 = {2 * n + 1} frames; use a smaller n"
        )
    step = _stepper(progress, 4)

    feats = frame_features(frames, feature_size)
    d = distance_matrix(feats)
    corr, rel = _distance_agreement(frames, d)
    step()

    sym_raw, sym = symmetry_scores(d, n=n, s=s, min_pairs=min_pairs)
    reduced = local_maxima(sym, r)
    reduced[reduced < min_symmetry] = 0.0
    turns = np.flatnonzero(reduced > 0).astype(np.int32)
    if turns.size < 2:
        raise InvalidArgumentError(
            f"found {turns.size} turn point(s) with symmetry >= min_symmetry={min_symmetry}; playback "
            f"needs at least 2: lower min_symmetry, r or n, or use a longer clip"
        )
    p_max = reduced / 2.0
    p_max[turns[0]] = p_max[turns[-1]] = 1.0
    step()

    allowed = None
    ghost_level = None
    flows = PairFlows(frames) if warp == "on" and can_flow(*frames.shape[1:3]) else None
    warp_wins: dict[tuple[int, int], bool] = {}
    if max_ghost > 0:
        ghosts = DoubleImages(frames)
        ghost_level = ghosts.level()

        def allowed(i: np.ndarray, j: np.ndarray) -> np.ndarray:
            ghost = crossfade_ghost(ghosts, i, j)
            # only a jump a plain crossfade would lose, by less than WARP_HOPE times, is tried warped
            bad = np.flatnonzero((ghost > max_ghost * ghost_level) & (ghost <= WARP_HOPE * max_ghost * ghost_level))
            bad = bad[np.argsort(ghost[bad], kind="stable")][: max(0, MAX_WARP_TRIES - len(warp_wins))]
            if flows is not None and bad.size:
                warped = warped_crossfade_ghost(flows, ghosts, i[bad], j[bad], CROSSFADE)
                warp_wins.update(zip(zip(i[bad].tolist(), j[bad].tolist()), (warped < ghost[bad]).tolist()))
                ghost[bad] = np.minimum(ghost[bad], warped)
            return ghost <= max_ghost * ghost_level

    src, dst, cost, fcost, prob, exit_frame = _transitions(
        d,
        taps=taps,
        p=p,
        alpha=alpha,
        sigma=sigma,
        min_gap=min_gap,
        min_prob=min_prob,
        max_per_frame=max_per_frame,
        max_cost=max_cost * float(np.median(np.diag(d, 1))),
        allowed=allowed,
    )
    step()
    consec = np.diag(d, 1)
    info = {
        "n": n,
        "s": s,
        "r": r,
        "min_pairs": min_pairs,
        "min_symmetry": min_symmetry,
        "feature_size": feature_size,
        "feature_values": int(feats.shape[1]),
        "taps": taps,
        "p": p,
        "alpha": alpha,
        "sigma": sigma,
        "min_gap": min_gap,
        "min_prob": min_prob,
        "max_per_frame": max_per_frame,
        "max_cost": max_cost,
        "max_ghost": max_ghost,
        "distance_correlation": corr,
        "distance_rel_error": rel,
        "median_step": float(np.median(consec)),
        "n_turn_points": int(turns.size),
        "n_transitions": int(src.size),
    }
    if ghost_level is not None:
        info["ghost_level"] = ghost_level
    flow = None
    if flows is not None:
        warped = [(a, b) for a, b in zip(src.tolist(), dst.tolist()) if warp_wins.get((a, b), max_ghost == 0)]
        flow = flows.model((o, n) for a, b in warped for o, n, _ in crossfade_pairs(a, b, CROSSFADE, t))
        info["n_warped"] = len(warped)
    info["warp"] = "off" if flows is None else "on"
    model = TurnPointModel(
        sym_raw=sym_raw,
        symmetry=sym,
        reduced=reduced,
        turn_points=turns,
        p_max=p_max,
        src=src,
        dst=dst,
        cost=cost,
        future_cost=fcost,
        prob=prob,
        exit_frame=exit_frame,
        info=info,
        flow=flow,
    )
    step()
    return model


def _transitions(
    d: np.ndarray,
    *,
    taps: int,
    p: float,
    alpha: float,
    sigma: float,
    min_gap: int,
    min_prob: float,
    max_per_frame: int,
    max_cost: float,
    allowed=None,
):
    t = d.shape[0]
    dp = filtered_distances(d, taps)
    # Jump i -> j replaces the successor i+1 by j: its cost compares i+1 with j.
    cost = np.full((t, t), np.inf)
    cost[:-1] = dp[1:]
    ii, jj = np.indices((t, t))
    near = np.abs(jj - (ii + 1)) < min_gap
    cost[near] = np.inf
    cost[cost > max_cost] = np.inf
    finite = np.isfinite(cost)
    empty = (np.zeros(0, np.int32),) * 2 + (np.zeros(0),) * 3
    if not finite.any():
        return (*empty, t - 1)
    cost_p = np.where(finite, cost, 0.0) ** p
    scale = float(cost_p[finite].mean()) or 1.0
    cost_p /= scale
    dead = 1e3
    cost_p[~finite] = np.inf
    checked = np.zeros((t, t), bool)
    for _ in range(MAX_GHOST_ROUNDS):
        # Jumps that ``allowed`` refuses are impossible: their neighbours may become the local
        # minima, and the future costs must not count on them.
        f, m = future_costs(cost_p, alpha, dead)
        keep = finite & _is_local_min(f)
        if allowed is None:
            break
        # only the few a frame could keep (the best ``max_per_frame``) are checked
        f_keep = np.where(keep, f, np.inf)
        top = np.zeros_like(keep)
        np.put_along_axis(top, np.argsort(f_keep, axis=1)[:, :max_per_frame], True, axis=1)
        ks, kd = np.nonzero(top & keep & ~checked)
        checked[ks, kd] = True
        bad = ~allowed(ks, kd)
        finite[ks[bad], kd[bad]] = False
        cost_p[ks[bad], kd[bad]] = np.inf
        keep &= finite
        if not bad.any():
            break
    # Per-visit probabilities: the continuation (cost alpha m[i+1]) competes with the jumps.
    cont = np.full(t, np.inf)
    cont[:-1] = alpha * m[1:]
    # Locally best, then the best few per frame.
    f_keep = np.where(keep, f, np.inf)
    order = np.argsort(f_keep, axis=1)[:, :max_per_frame]
    sel = np.zeros_like(keep)
    np.put_along_axis(sel, order, True, axis=1)
    keep &= sel
    base = np.minimum(cont, f_keep.min(axis=1))[:, None]
    base = np.where(np.isfinite(base), base, 0.0)
    ew = np.exp(-np.where(keep, f - base, np.inf) / sigma)
    ec = np.exp(-np.where(np.isfinite(cont), cont - base[:, 0], np.inf) / sigma)
    denom = ew.sum(axis=1) + ec
    prob = np.where(keep, ew / np.where(denom > 0, denom, 1)[:, None], 0.0)
    keep &= prob >= min_prob
    if allowed is not None:
        _late_exit(keep, prob, f, finite, allowed, min_prob)
    # Forward play must never run off the end: find the exit frame, the last frame with a
    # kept backward jump, drop everything beyond it and always jump there.
    while True:
        back = keep & (jj < ii)
        rows = np.flatnonzero(back.any(axis=1))
        if rows.size == 0:
            # No backward jump survived the thresholds: keep the single best one (the best
            # of the few cheapest that pass ``allowed``, else the cheapest).
            fb = np.where(finite & (jj < ii), f, np.inf)
            i, j = np.unravel_index(int(np.argmin(fb)), fb.shape)
            if not np.isfinite(fb[i, j]):
                return (*empty, t - 1)
            if allowed is not None:
                order = np.argsort(fb, axis=None)[:64]
                order = order[np.isfinite(fb.ravel()[order])]
                ci, cj = np.unravel_index(order, fb.shape)
                ok = np.flatnonzero(allowed(ci, cj))
                if ok.size:
                    i, j = ci[ok[0]], cj[ok[0]]
            keep[i, j] = True
            prob[i, j] = max(prob[i, j], min_prob)
            continue
        exit_frame = int(rows.max())
        beyond = (ii > exit_frame) | (jj > exit_frame)
        if not (keep & beyond).any():
            break
        keep &= ~beyond
    row = keep[exit_frame] & (np.arange(t) < exit_frame)
    keep[exit_frame] = row
    prob[exit_frame] = np.where(row, np.exp(-(f[exit_frame] - f[exit_frame][row].min()) / sigma), 0.0)
    prob[exit_frame] /= prob[exit_frame].sum()
    src, dst = np.nonzero(keep)
    return (
        src.astype(np.int32),
        dst.astype(np.int32),
        cost[src, dst].astype(np.float64),
        f[src, dst].astype(np.float64),
        np.clip(prob[src, dst], 0.0, 1.0),
        exit_frame,
    )


def _late_exit(keep, prob, f, finite, allowed, min_prob: float, tries: int = 8, block: int = 16) -> None:
    """Keep the best clean backward jump of the latest frame that has one, when it lies beyond
    every kept backward jump: refusing double-image jumps must not leave the clip's end unused.
    Rows are checked from the end in blocks (one ``allowed`` call each)."""
    t = keep.shape[0]
    back = np.flatnonzero((keep & np.tri(t, k=-1, dtype=bool)).any(axis=1))
    first = int(back.max()) + 1 if back.size else 0
    for top in range(t - 2, first - 1, -block):
        rows, cols = [], []
        for i in range(top, max(first, top - block + 1) - 1, -1):
            cands = np.flatnonzero(finite[i, :i])
            cands = cands[np.argsort(f[i, cands])][:tries]
            rows += [i] * cands.size
            cols += cands.tolist()
        if not rows:
            continue
        ok = np.flatnonzero(allowed(np.array(rows), np.array(cols)))
        if ok.size:  # rows run from the latest down, each row's candidates best first
            i, j = rows[ok[0]], cols[ok[0]]
            keep[i, j] = True
            prob[i, j] = max(prob[i, j], min_prob)
            return


def crossfade_ghost(
    frames: np.ndarray | DoubleImages, i: np.ndarray, j: np.ndarray, crossfade: int = CROSSFADE
) -> np.ndarray:
    """The largest :func:`~dynatex.analyzer.metrics.double_image` of the crossfaded frames of
    each jump ``i[k] -> j[k]`` of ``frames`` (or a :class:`DoubleImages` of them), played
    forward and mirrored backward, ``(len(i),)``.

    Forward, the jump shows ``j + m - 1`` faded in over ``i + m`` for ``m = 1..crossfade``
    (weight ``m / (crossfade + 1)``); backward (hybrid play's mirror ``j + 1 -> i + 1``),
    ``i + 2 - m`` over ``j + 1 - m``. Pairs that leave the clip are not shown by the player.
    """
    ghosts = frames if isinstance(frames, DoubleImages) else DoubleImages(frames)
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    t = len(ghosts.rows)
    if i.size == 0:
        return np.zeros(0)
    m = np.arange(1, crossfade + 1)
    w = np.broadcast_to(m / (crossfade + 1), (i.size, crossfade))
    old = np.concatenate([i[:, None] + m, j[:, None] + 1 - m], axis=1)
    new = np.concatenate([j[:, None] + m - 1, i[:, None] + 2 - m], axis=1)
    w = np.concatenate([w, w], axis=1)
    ok = (old >= 0) & (old < t) & (new >= 0) & (new < t)
    ghost = np.zeros(old.shape)
    ghost[ok] = ghosts.crossfades(old[ok], new[ok], w[ok])
    return ghost.max(axis=1)


def _is_local_min(f: np.ndarray) -> np.ndarray:
    """Entries no larger than their 8 neighbours (``inf`` padding)."""
    pad = np.pad(f, 1, constant_values=np.inf)
    t0, t1 = f.shape
    out = np.ones(f.shape, bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                out &= f <= pad[1 + di : 1 + di + t0, 1 + dj : 1 + dj + t1]
    return out


def _distance_agreement(frames: np.ndarray, d: np.ndarray, samples: int = 64) -> tuple[float, float]:
    """Correlation and relative RMS error (after the best scale fit) of the reduced distances
    against full-resolution L2, on consecutive pairs and ``samples`` random pairs."""
    t = frames.shape[0]
    rng = np.random.default_rng(0)
    pairs = [(i, i + 1) for i in range(0, t - 1, max(1, (t - 1) // samples))]
    pairs += [tuple(sorted(rng.choice(t, 2, replace=False))) for _ in range(samples)]
    full = np.array(
        [math.sqrt(float(np.sum((frames[i].astype(np.float32) - frames[j]) ** 2, dtype=np.float64))) for i, j in pairs]
    )
    red = np.array([d[i, j] for i, j in pairs])
    if full.std() == 0 or red.std() == 0:
        return 1.0, 0.0
    corr = float(np.corrcoef(full, red)[0, 1])
    k = float(np.dot(full, red) / np.dot(red, red))  # best scale: reduced frames lose fine detail
    rel = float(np.sqrt(np.mean((k * red - full) ** 2)) / np.sqrt(np.mean(full**2)))
    return corr, rel


def pendulum_clip(
    frames: int = 120,
    size: int = 64,
    *,
    period: float = 26.4,
    phase: float = 3.3,
    amplitude: float = 0.6,
    noise: float = 2.0,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """A rendered swinging pendulum with known extremes, for tests and demos.

    The angle is ``amplitude * cos(2 pi (t - phase) / period)``, so the swing turns at
    ``t = phase + k period / 2``. Returns ``(frames, extremes)``: ``(T, size, size, 3)``
    uint8 frames (anti-aliased rod and bob over a textured background, light noise) and
    the extreme times (float) inside ``[0, T - 1]``.

    Examples
    --------
    >>> frames, extremes = pendulum_clip(40, 32)
    >>> frames.shape, np.round(extremes, 1).tolist()
    ((40, 32, 32, 3), [3.3, 16.5, 29.7])
    """
    t = np.arange(frames, dtype=np.float64)
    theta = amplitude * np.cos(2 * np.pi * (t - phase) / period)
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64) + 0.5
    px, py = size / 2, size * 0.08
    length = size * 0.72
    rng = np.random.default_rng(seed)
    bg = 90 + 25 * np.sin(xx / size * 7) * np.cos(yy / size * 5)
    out = np.empty((frames, size, size, 3), np.uint8)
    for i, th in enumerate(theta):
        bx, by = px + length * np.sin(th), py + length * np.cos(th)
        # distance to the rod segment and to the bob, turned into anti-aliased coverage
        vx, vy = bx - px, by - py
        u = np.clip(((xx - px) * vx + (yy - py) * vy) / (vx * vx + vy * vy), 0, 1)
        d_rod = np.hypot(xx - (px + u * vx), yy - (py + u * vy))
        d_bob = np.hypot(xx - bx, yy - by)
        rod = np.clip(1.5 - d_rod / (size / 64), 0, 1)
        bob = np.clip(size * 0.09 - d_bob + 0.5, 0, 1)
        img = bg * (1 - np.maximum(rod, bob))
        rgb = np.stack([img + 200 * bob + 40 * rod, img + 170 * bob + 40 * rod, img + 60 * bob + 40 * rod], -1)
        rgb += rng.normal(0, noise, rgb.shape)
        out[i] = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    k = np.arange(-1, int(frames / (period / 2)) + 2)
    ext = phase + k * period / 2
    return out, ext[(ext >= 0) & (ext <= frames - 1)]


# -- checks ---------------------------------------------------------------------------
def _int(name: str, value, lo: int) -> int:
    return check_int(name, value, lo, rule=f"at least {lo}")


def plot_turnpoints(model: TurnPointModel, path: str, *, title: str | None = None) -> str:
    """Write a PNG like the seed's Figure 2: symmetry (grey), maximum reversal probabilities
    (red), initial probabilities (green), turn points, and below it the kept transitions.

    Examples
    --------
    >>> frames = np.zeros((30, 8, 8, 3), np.uint8)
    >>> frames[:, :, :, 0] = (100 + 80 * np.cos(np.arange(30) / 3)).astype(np.uint8)[:, None, None]
    >>> plot_turnpoints(learn_turnpoints(frames, n=3), "/tmp/tp_doctest.png")   # doctest: +ELLIPSIS
    '/tmp/tp_doctest.png'
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    t = model.n_frames
    x = np.arange(t)
    p_init = model.p_max / 2.0
    p_init[[model.first_turn, model.last_turn]] = 1.0
    fig = Figure(figsize=(9, 5.5), dpi=100)
    ax, bx = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    ax.fill_between(x, model.symmetry, color="0.75", step="mid", label="symmetry (eq. 3)")
    ax.vlines(x, 0, model.p_max, color="tab:red", lw=3, label="max reversal probability (eq. 5)")
    ax.vlines(x + 0.25, 0, p_init, color="tab:green", lw=2, label="initial probability (eq. 6)")
    ax.plot(model.turn_points, model.symmetry[model.turn_points], "kv", ms=6, label="turn points")
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("value")
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    ax.set_title(title or "turn points")
    if model.src.size:
        sc = bx.scatter(model.src, model.dst, c=model.prob, cmap="viridis", vmin=0, vmax=1, s=18)
        fig.colorbar(sc, ax=(ax, bx), label="jump probability", fraction=0.04)
    bx.axvline(model.exit_frame, color="tab:orange", ls="--", lw=1, label="exit frame")
    bx.plot([0, t - 1], [1, t], color="0.6", lw=0.8, label="natural successor")
    bx.set_xlabel("source frame")
    bx.set_ylabel("transition target")
    bx.set_xlim(-0.5, t - 0.5)
    bx.legend(loc="upper left", fontsize=7)
    fig.savefig(path)
    return path
