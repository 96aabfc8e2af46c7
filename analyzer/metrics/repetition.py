"""Coverage and repetition in time: how much of the source an output shows, and after how many
frames it repeats itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import check_frames, check_int
from ...errors import ArgumentTypeError, InvalidArgumentError
from ._common import POSITIVE, luma, same_size, thumb_size


# -- coverage and repetition ------------------------------------------------------------------
def index_coverage(indices: Any, n_source: int) -> float:
    """Share of the ``n_source`` source frames (or tiles) that appear in ``indices``.

    Examples
    --------
    >>> index_coverage([0, 1, 1, 3], 8)
    0.375
    """
    n_source = check_int("n_source", n_source, 1)
    idx = np.asarray(indices)
    if idx.size == 0:
        raise InvalidArgumentError("indices is empty")
    if idx.dtype.kind not in "ui":
        raise ArgumentTypeError(f"indices must be integers, not {idx.dtype}")
    if idx.min() < 0 or idx.max() >= n_source:
        raise InvalidArgumentError(f"indices must lie in 0..{n_source - 1}, found {int(idx.min())}..{int(idx.max())}")
    return float(np.unique(idx).size) / n_source


def frame_coverage(output: np.ndarray, source: np.ndarray) -> float:
    """Share of source frames that are the nearest source frame of at least one output frame.

    Frames are compared as luma thumbnails (longer side 32 pixels) by Euclidean distance.
    1 when the output shows every source frame; ``1/T`` for a frozen frame.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (10, 8, 8)).astype(np.uint8)
    >>> frame_coverage(clip, clip), frame_coverage(clip[[3] * 10], clip)
    (1.0, 0.1)
    """
    output = check_frames(output, name="output")
    source = check_frames(source, name="source")
    same_size(output, source, "frame_coverage")
    size = thumb_size(source.shape)
    to = luma(output, size=size).reshape(output.shape[0], -1)
    ts = luma(source, size=size).reshape(source.shape[0], -1)
    return index_coverage(_nearest_rows(to, ts), source.shape[0])


def _nearest_rows(q: np.ndarray, db: np.ndarray) -> np.ndarray:
    q64, db64 = q.astype(np.float64), db.astype(np.float64)
    dbn = np.einsum("ij,ij->i", db64, db64)
    out = np.empty(len(q), np.int64)
    for i in range(0, len(q), 1024):
        out[i : i + 1024] = np.argmin(dbn[None, :] - 2.0 * (q64[i : i + 1024] @ db64.T), axis=1)
    return out


def repetition_profile(
    output: np.ndarray, *, source: np.ndarray | None = None, max_lag: int | None = None
) -> np.ndarray:
    """Mean frame difference at each lag, over the reference's median consecutive-frame difference.

    ``profile[L - 1]`` is the mean over ``t`` of the RMS difference between luma thumbnails
    (longer side 32 pixels) of output frames ``t`` and ``t + L``, divided by the median
    difference between consecutive thumbnails of ``source`` (of the output when None).

    Parameters
    ----------
    output : ndarray
        ``(T, H, W[, C])`` clip, at least 2 frames.
    source : ndarray, optional
        Reference clip (any size) for the normalisation.
    max_lag : int, optional
        Largest lag (default ``T // 2``, at most ``T - 1``).

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (12, 8, 8)).astype(np.uint8)
    >>> prof = repetition_profile(np.concatenate([clip[:4]] * 3))
    >>> int(np.argmin(prof)) + 1, float(prof.min())
    (4, 0.0)
    """
    output = check_frames(output, name="output", min_frames=2)
    t = output.shape[0]
    max_lag = max(1, t // 2) if max_lag is None else check_int("max_lag", max_lag, 1, t - 1)
    to = luma(output, size=thumb_size(output.shape)).reshape(t, -1).astype(np.float64)
    to -= to.mean(axis=0)  # smaller norms: less cancellation in the Gram-matrix distances
    if source is None:
        ref_thumbs = to
    else:
        source = check_frames(source, name="source", min_frames=2)
        ref_thumbs = luma(source, size=thumb_size(source.shape)).reshape(source.shape[0], -1).astype(np.float64)
    dr = np.diff(ref_thumbs, axis=0)
    ref = float(np.median(np.sqrt(np.mean(dr * dr, axis=1))))
    if ref <= 0:
        ref = 1e-3  # a frozen reference: any change counts as large
    d = to.shape[1]
    norms = np.einsum("ij,ij->i", to, to)
    sums = np.zeros(max_lag + 1)
    counts = np.zeros(max_lag + 1)
    for i0 in range(0, t, 512):
        i1 = min(t, i0 + 512)
        j1 = min(t, i1 + max_lag)
        d2 = norms[i0:i1, None] + norms[None, i0:j1] - 2.0 * (to[i0:i1] @ to[i0:j1].T)
        lag = np.arange(i0, j1)[None, :] - np.arange(i0, i1)[:, None]
        m = (lag >= 1) & (lag <= max_lag)
        rms = np.sqrt(np.maximum(d2[m], 0.0) / d)
        sums += np.bincount(lag[m], weights=rms, minlength=max_lag + 1)
        counts += np.bincount(lag[m], minlength=max_lag + 1)
    prof = sums[1:] / counts[1:] / ref
    prof[prof < 1e-6] = 0.0  # rounding of the Gram-matrix distances
    return prof


def repetition_lag(
    output: np.ndarray, *, source: np.ndarray | None = None, tolerance: float = 0.25, max_lag: int | None = None
) -> int | None:
    """Earliest lag at which the output repeats itself, or None when it does not within ``max_lag``.

    The output repeats at lag ``L`` when :func:`repetition_profile` at ``L`` is at most
    ``tolerance`` (a fraction of the reference's median consecutive-frame difference).

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (30, 8, 8)).astype(np.uint8)
    >>> repetition_lag(np.concatenate([clip[:5]] * 6), source=clip), repetition_lag(clip)
    (5, None)
    """
    tolerance = POSITIVE.check("tolerance", tolerance)
    prof = repetition_profile(output, source=source, max_lag=max_lag)
    hits = np.flatnonzero(prof <= tolerance)
    return int(hits[0]) + 1 if hits.size else None
