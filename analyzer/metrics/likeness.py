"""Likeness to the source: the spatio-temporal power spectrum, patch coherence and completeness."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import check_frames, check_int
from ...errors import InvalidArgumentError
from ._common import POSITIVE, auto_downscale, int_pair, luma
from .memo import remembered


# -- likeness: spatio-temporal power spectrum ------------------------------------------------
def st_power_spectrum(frames: np.ndarray, *, cuboid: Sequence[int] = (16, 32), downscale: int = 1) -> np.ndarray:
    """Binned spatio-temporal power spectrum (Welch estimate) of a clip's luma.

    The luma, area-downscaled by ``downscale``, is cut into cuboids of ``cuboid[0]`` frames
    by ``cuboid[1]`` x ``cuboid[1]`` pixels, overlapping by half in every axis. Each cuboid
    loses its mean, is multiplied by a 3-D Hann window and Fourier transformed; power is
    averaged over cuboids and then over the coefficients of each bin: temporal frequency
    ``|f_t| * cuboid[0]`` (rows, 0 .. cuboid[0]/2) by radial spatial frequency
    ``round(|f_xy| * cuboid[1])`` (columns, 0 .. cuboid[1]/2; corners beyond are dropped).

    Returns
    -------
    ndarray
        ``(cuboid[0] // 2 + 1, cuboid[1] // 2 + 1)`` mean power per coefficient (grey levels^2).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> st_power_spectrum(rng.normal(128, 20, (16, 32, 32)).clip(0, 255), cuboid=(8, 16)).shape
    (5, 9)
    """
    frames = check_frames(frames, name="frames")
    ct, cs = int_pair("cuboid", cuboid, 2)
    downscale = check_int("downscale", downscale, 1)
    grey = luma(frames, downscale)
    return _spectrum(grey, ct, cs)


@remembered
def _spectrum(grey: np.ndarray, ct: int, cs: int) -> np.ndarray:
    from numpy.lib.stride_tricks import sliding_window_view

    t, h, w = grey.shape
    if t < ct or h < cs or w < cs:
        raise InvalidArgumentError(
            f"clip ({t} frames of {w}x{h} after downscaling) is smaller than the "
            f"spectrum cuboid ({ct} frames of {cs}x{cs})"
        )
    win = (
        np.hanning(ct + 2)[1:-1, None, None]
        * np.hanning(cs + 2)[1:-1][None, :, None]
        * np.hanning(cs + 2)[1:-1][None, None, :]
    ).astype(np.float32)
    st, ss = max(1, ct // 2), max(1, cs // 2)
    acc = np.zeros((ct, cs, cs // 2 + 1), np.float64)
    count = 0
    for t0 in range(0, t - ct + 1, st):
        block = grey[t0 : t0 + ct]
        cub = sliding_window_view(block, (cs, cs), axis=(1, 2))[:, ::ss, ::ss]  # (ct, ny, nx, cs, cs)
        cub = np.moveaxis(cub, 0, 2).reshape(-1, ct, cs, cs)
        cub = cub - cub.mean(axis=(1, 2, 3), keepdims=True)
        spec = np.fft.rfftn(cub * win, axes=(1, 2, 3))
        acc += (spec.real**2 + spec.imag**2).sum(axis=0)
        count += cub.shape[0]
    acc /= count
    ft = np.rint(np.abs(np.fft.fftfreq(ct)) * ct).astype(int)
    fy = np.fft.fftfreq(cs)
    fx = np.fft.rfftfreq(cs)
    fr = np.rint(np.sqrt(fy[:, None] ** 2 + fx[None, :] ** 2) * cs).astype(int)
    nt, nr = ct // 2 + 1, cs // 2 + 1
    keep = np.broadcast_to(fr <= nr - 1, acc.shape)
    idx = ft[:, None, None] * nr + fr[None, :, :]
    idx = np.broadcast_to(idx, acc.shape)[keep]
    sums = np.bincount(idx, weights=acc[keep], minlength=nt * nr)
    cnts = np.bincount(idx, minlength=nt * nr)
    return (sums / np.maximum(cnts, 1)).reshape(nt, nr)


def spectrum_distance(
    output: np.ndarray,
    source: np.ndarray,
    *,
    cuboid: Sequence[int] = (16, 32),
    downscale: int | None = None,
    floor: float = 1e-3,
) -> float:
    """RMS difference, in dB, between the binned spatio-temporal power spectra of output and source.

    Both spectra come from :func:`st_power_spectrum` with the same cuboid and downscale
    factor, so clips of different sizes and lengths compare. The DC bin is left out; each
    bin's power gets ``floor`` times the source's mean bin power added before the log, which
    bounds the distance when the output has no power in a bin (a frozen clip). 0 dB is
    identical statistics.

    Parameters
    ----------
    output, source : ndarray
        ``(T, H, W[, C])`` clips.
    cuboid : (frames, pixels)
        Cuboid size; shrunk to fit the shorter or smaller of the two clips.
    downscale : int, optional
        Area-downscale factor (default ``max(1, min(H, W) // 128)`` of the source).
    floor : float
        Relative power floor.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> clip = rng.normal(128, 20, (16, 32, 32)).clip(0, 255)
    >>> spectrum_distance(clip, clip, cuboid=(8, 16))
    0.0
    """
    output = check_frames(output, name="output", min_frames=2)
    source = check_frames(source, name="source", min_frames=2)
    floor = POSITIVE.check("floor", floor)
    f = auto_downscale(source, downscale)
    ct, cs = int_pair("cuboid", cuboid, 2)
    go, gs = luma(output, f), luma(source, f)
    ct = min(ct, go.shape[0], gs.shape[0])
    cs = min(cs, *go.shape[1:], *gs.shape[1:])
    if ct < 4 or cs < 4:
        raise InvalidArgumentError(
            f"clips too small for a power spectrum: need at least 4 frames and 4x4 pixels "
            f"after downscaling by {f}, got {ct} frames and {cs} pixels"
        )
    po, ps = _spectrum(go, ct, cs), _spectrum(gs, ct, cs)
    mask = np.ones(po.shape, bool)
    mask[0, 0] = False
    fl = floor * float(ps[mask].mean()) + 1e-12
    d = 10.0 * np.log10((po[mask] + fl) / (ps[mask] + fl))
    return float(np.sqrt(np.mean(d * d)))


# -- likeness: patch coherence and completeness ----------------------------------------------
def _patches(grey: np.ndarray, pt: int, ps: int, st: int, ss: int) -> tuple[np.ndarray, tuple[int, int, int]]:
    from numpy.lib.stride_tricks import sliding_window_view

    t, h, w = grey.shape
    if t < pt or h < ps or w < ps:
        raise InvalidArgumentError(
            f"clip ({t} frames of {w}x{h} after downscaling) is smaller than one patch ({pt} frames of {ps}x{ps})"
        )
    v = sliding_window_view(grey, (pt, ps, ps))[::st, ::ss, ::ss]
    return v, v.shape[:3]


def _project(view: np.ndarray, idx: np.ndarray | None, mean: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Patches of ``view`` (all, or the flat indices ``idx``) centred and projected on ``basis``."""
    grid = view.shape[:3]
    d = mean.size
    if idx is None:
        idx = np.arange(int(np.prod(grid)))
    out = np.empty((len(idx), basis.shape[1]), np.float32)
    for i in range(0, len(idx), 8192):
        sel = np.unravel_index(idx[i : i + 8192], grid)
        p = view[sel].reshape(-1, d) - mean
        out[i : i + len(p)] = p @ basis
    return out


@remembered
def _source_patches(
    grey: np.ndarray, pt: int, ps: int, st: int, ss: int, n_components: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """:func:`patch_distances`' source side from the source's luma ``grey``: the mean patch, the
    principal axes, every source patch projected on them, and the random state after the fit's draw."""
    vs, gs = _patches(grey, pt, ps, st, ss)
    d = pt * ps * ps
    rng = np.random.default_rng(seed)
    n_src = int(np.prod(gs))
    fit_idx = rng.choice(n_src, size=min(n_src, 20000), replace=False)
    fit = vs[np.unravel_index(fit_idx, gs)].reshape(-1, d).astype(np.float64)
    mean = fit.mean(axis=0)
    cov = np.cov(fit - mean, rowvar=False) if len(fit) > 1 else np.zeros((d, d))
    vals, vecs = np.linalg.eigh(np.atleast_2d(cov))
    basis = np.ascontiguousarray(vecs[:, ::-1][:, : min(n_components, d)]).astype(np.float32)
    mean32 = mean.astype(np.float32)
    return mean32, basis, _project(vs, None, mean32, basis), rng.bit_generator.state


def _nn_dist(q: np.ndarray, db: np.ndarray) -> np.ndarray:
    """Euclidean distance from each row of ``q`` to its nearest row of ``db`` (brute force, chunked).

    The search runs on float32 dot products; the winner's distance is then recomputed
    exactly, so a patch found in ``db`` has distance 0.
    """
    best = np.full(len(q), np.inf, np.float32)
    arg = np.zeros(len(q), np.int64)
    dbn = np.einsum("ij,ij->i", db, db)
    for j in range(0, len(db), 16384):
        d2 = dbn[None, j : j + 16384] - 2.0 * (q @ db[j : j + 16384].T)
        k = d2.argmin(axis=1)
        v = d2[np.arange(len(q)), k]
        better = v < best
        best[better] = v[better]
        arg[better] = k[better] + j
    diff = q.astype(np.float64) - db[arg].astype(np.float64)
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def patch_distances(
    output: np.ndarray,
    source: np.ndarray,
    *,
    patch: Sequence[int] = (3, 5),
    stride: Sequence[int] = (2, 3),
    n_samples: int = 1000,
    n_components: int = 16,
    downscale: int | None = None,
    seed: int = 0,
) -> tuple[float, float]:
    """Nearest-neighbour spatio-temporal patch coherence and completeness, ``(coherence, completeness)``.

    Both clips become luma, area-downscaled by ``downscale``. A patch is ``patch[0]`` frames
    by ``patch[1]`` x ``patch[1]`` pixels, taken on a grid of ``stride[0]`` frames and
    ``stride[1]`` pixels. Patches are centred on the source's mean patch and projected on
    the source patches' ``n_components`` leading principal components. *Coherence*:
    ``n_samples`` output patches drawn at random (``seed``) from the output's grid, each
    matched to its nearest patch of the source grid. *Completeness*: the same with the roles
    swapped. Each is the mean nearest distance expressed as RMS grey levels per patch pixel
    (0 = every patch found exactly).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clip = rng.integers(0, 256, (8, 16, 16)).astype(np.uint8)
    >>> [round(v, 3) for v in patch_distances(clip, clip, n_samples=50, downscale=1)]
    [0.0, 0.0]
    """
    output = check_frames(output, name="output")
    source = check_frames(source, name="source")
    pt, ps = int_pair("patch", patch, 1)
    st, ss = int_pair("stride", stride, 1)
    n_samples = check_int("n_samples", n_samples, 1)
    n_components = check_int("n_components", n_components, 1)
    seed = check_int("seed", seed, 0)
    f = auto_downscale(source, downscale)
    vo, go = _patches(luma(output, f), pt, ps, st, ss)
    mean32, basis, src_all, state = _source_patches(luma(source, f), pt, ps, st, ss, n_components, seed)
    d = pt * ps * ps
    rng = np.random.default_rng(seed)
    rng.bit_generator.state = state
    n_src, n_out = len(src_all), int(np.prod(go))
    out_all = _project(vo, None, mean32, basis)
    q_out = out_all[rng.choice(n_out, size=min(n_out, n_samples), replace=False)]
    q_src = src_all[rng.choice(n_src, size=min(n_src, n_samples), replace=False)]
    coherence = float(_nn_dist(q_out, src_all).mean()) / math.sqrt(d)
    completeness = float(_nn_dist(q_src, out_all).mean()) / math.sqrt(d)
    return coherence, completeness


def patch_coherence(output: np.ndarray, source: np.ndarray, **options: Any) -> float:
    """Mean distance from output patches to their nearest source patch (see :func:`patch_distances`).

    Low: every piece of the output looks like some piece of the source.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (8, 16, 16)).astype(np.uint8)
    >>> round(patch_coherence(clip, clip, n_samples=50, downscale=1), 3)
    0.0
    """
    return patch_distances(output, source, **options)[0]


def patch_completeness(output: np.ndarray, source: np.ndarray, **options: Any) -> float:
    """Mean distance from source patches to their nearest output patch (see :func:`patch_distances`).

    Low: every piece of the source shows up somewhere in the output.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (8, 16, 16)).astype(np.uint8)
    >>> round(patch_completeness(clip, clip, n_samples=50, downscale=1), 3)
    0.0
    """
    return patch_distances(output, source, **options)[1]
