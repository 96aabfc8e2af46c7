"""Learning linear dynamic textures (Doretto & Soatto), with stability enforced.

``x(t+1) = A x(t) + B v(t)``, ``frame(t) = C x(t) + mean``: ``C`` from an SVD of the
mean-subtracted clip (through the small ``tau x tau`` Gram matrix, or a randomized SVD),
``A`` by least squares on the states, ``B`` from the residuals with the
``1/sqrt(tau - 1)`` normalisation the seed's pseudocode leaves out, so that the
synthesized state covariance matches the training one.

A :class:`~dynatex.analyzer.stream.DiskClip` is learned out of core: the Gram matrix is
summed over blocks of pixel columns read from disk and the basis is projected block by
block, so the float32 clip never exists in memory; ``max_memory`` sizes the blocks.

An in-memory clip also gets the model's ``detail`` part (:mod:`.detail`): the truncation
residual as a noise texture with its colour axes and spatio-temporal spectrum, and the
source's per-pixel colour range; a streamed clip is learned without it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..checks import check_int
from ..errors import InvalidArgumentError
from ..tiledb import LDSModel
from .deblock import choose as choose_grid
from .deblock import learning_values
from .detail import attach_detail
from .gamut import learn_gamut
from .methods import check_params
from .signs import canonical_signs, orient_rows
from .stream import DiskClip
from .tone import choose as choose_tone
from .tone import level_gain, levels_of
from .video import Clip, Progress, clip_frames

DEFAULT_N = 50
DEFAULT_MAX_RADIUS = 0.995
#: Default bound of an out-of-core learn when none is given.
DEFAULT_MAX_MEMORY = 2 << 30
#: Memory assumed taken before learning starts (interpreter, numpy, h5py, OpenCV).
BASE_MEMORY = 320 << 20


def learn_lds(
    clip: Clip | DiskClip | np.ndarray,
    *,
    n: int | str = DEFAULT_N,
    k: int | None = None,
    energy: float = 0.9,
    svd: str = "auto",
    max_radius: float = DEFAULT_MAX_RADIUS,
    calibrate: bool = True,
    tone: str = "auto",
    deblock: str = "auto",
    seed: int = 0,
    max_memory: int | None = None,
    progress: Progress | None = None,
) -> LDSModel:
    """Learn a linear dynamic texture from a clip.

    Parameters
    ----------
    clip : Clip, DiskClip or ndarray
        Frames ``(T, H, W, C)`` uint8 (or a :class:`~dynatex.analyzer.Clip`). A
        :class:`~dynatex.analyzer.stream.DiskClip` is learned out of core, always through
        the exact Gram matrix (``svd`` is ignored).
    n : int or "auto"
        State order. ``"auto"`` picks the smallest order whose components hold ``energy``
        of the clip's variance (at least 2, at most ``min(T - 1, 50)``).
    k : int, optional
        Rank of the driving noise, ``1 <= k <= n`` (default ``n``).
    energy : float
        Variance fraction for ``n="auto"``, in (0, 1].
    svd : {"auto", "gram", "randomized"}
        ``"gram"`` diagonalises the ``T x T`` Gram matrix (exact); ``"randomized"`` uses a
        randomized range finder (for long clips); ``"auto"`` picks gram for ``T <= 1500``.
    max_radius : float
        Largest pole magnitude allowed; least-squares poles beyond it are pulled back to it.
    calibrate : bool
        Scale ``Q`` so that the stationary state variance equals the training states'
        (stability clipping otherwise changes the texture's energy); with a tone map, then so
        that the model's draws mapped back to levels have the variance its training states'
        reconstructions have there (:func:`.tone.level_gain`; info ``level_gain``).
    tone : {"auto", "on", "off"}
        Learn on the clip's levels Gaussianised per channel (:mod:`.tone`; the model's ``tone``
        part maps them back): "auto" where a Gaussian model would saturate many values. A
        streamed clip is learned on its levels ("on" is refused).
    deblock : {"auto", "on", "off"}
        Smooth away the block grid of a compressed clip before learning (:mod:`.deblock`): "auto"
        where one is found, "on" on every plane and axis, "off" never; the model's info records
        the grid (``codec_grid``) and whether it was smoothed (``deblocked``). A streamed clip is
        learned as it is ("on" is refused).
    seed : int
        Seed of the randomized SVD.
    max_memory : int, optional
        Bytes an out-of-core learn may use in all, the returned model and the database
        write included (default 2 GiB); too small a bound for the clip is a ValueError.
    progress : callable(done, total), optional
        Called after each of the 5 stages.

    Returns
    -------
    LDSModel

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(40)[:, None, None, None]
    >>> x = np.arange(16)[None, None, :, None]
    >>> frames = (128 + 60 * np.sin(0.3 * t + 0.5 * x) + 0 * np.arange(8)[None, :, None, None]).astype(np.uint8)
    >>> model = learn_lds(np.repeat(frames, 3, axis=3), n=4)
    >>> model.basis.shape, bool(model.info["spectral_radius"] < 1)
    ((4, 384), True)
    """
    streamed = isinstance(clip, DiskClip)
    frames = None if streamed else clip_frames(clip)
    tau = clip.n_frames if streamed else frames.shape[0]
    if tau < 3:
        raise InvalidArgumentError(f"clip has {tau} frames; learning an LDS needs at least 3")
    n, k, energy, svd, max_radius, calibrate, tone, deblock, seed = check_params(
        "lds",
        n=n,
        k=k,
        energy=energy,
        svd=svd,
        max_radius=max_radius,
        calibrate=calibrate,
        tone=tone,
        deblock=deblock,
        seed=seed,
    )
    auto = n == "auto"
    if not auto:
        if n > tau - 1:
            raise InvalidArgumentError(f"n={n} is larger than the clip allows: it has {tau} frames, so n <= {tau - 1}")
    tone_map = choose_tone(frames, tone)
    grid, grid_info = choose_grid(frames, deblock)
    step = _stepper(progress, 5)
    rank_cap = min(tau - 1, DEFAULT_N) if auto else int(n)
    if streamed:
        mean, basis, sv, states, total_energy, blocks = _learn_subspace_streamed(
            clip, rank_cap, energy if auto else None, max_memory, step
        )
        method = "gram-streamed"
    else:
        values, learned = learning_values(frames, grid, tone_map)
        mean, basis, sv, states, total_energy, method = _learn_subspace(values, svd, auto, rank_cap, seed, step)
        del values
        blocks = 0
    if auto:
        cum = np.cumsum(sv**2) / total_energy
        n = int(np.clip(np.searchsorted(cum, energy) + 1, 2, rank_cap))
    n = int(n)
    keep = sv[:n] > sv[0] * 1e-6
    if not keep.all():
        raise InvalidArgumentError(
            f"n={n} exceeds the clip's rank ({int(keep.sum())} independent components); use a smaller n"
        )
    basis = np.ascontiguousarray(basis[:n])
    x = states[:n].astype(np.float64)
    k = n if k is None else k
    k = check_int("k", k, 1, n, rule=f"an integer in 1..n={n}")
    step()
    model = _fit_dynamics(mean, basis, sv, x, total_energy, tau, k, max_radius, calibrate, energy, auto, method, step)
    model.info.update(grid_info)
    if streamed:
        model.info["column_blocks"] = int(blocks)
    else:
        if calibrate and tone_map is not None:
            gain = level_gain(mean, model.basis, model.stationary_cov, x, tone_map)
            model.B = model.B * np.sqrt(gain)
            model.stationary_cov = model.stationary_cov * gain
            model.info["level_gain"] = gain
        basis32, x32 = model.basis, x.T.astype(np.float32)
        attach_detail(model, learned, levels_of(lambda t0, t1: x32[t0:t1] @ basis32 + mean, tone_map), seed=seed)
        model.gamut = learn_gamut(frames)
        model.tone = tone_map
    return model


def _learn_subspace(frames: np.ndarray, svd: str, auto: bool, rank_cap: int, seed: int, step):
    """In memory: mean, basis, singular values, states and total energy of the clip (``(T, H, W, C)``
    uint8, or float32 tone values ``(T, P)``, which are used up: mean-subtracted in place)."""
    tau = frames.shape[0]
    # One float32 copy of the clip, mean-subtracted in place.
    y = frames.reshape(tau, -1).astype(np.float32, copy=False)
    mean = y.mean(axis=0, dtype=np.float64).astype(np.float32)
    y -= mean
    total_energy = float(np.einsum("ij,ij->", y, y, dtype=np.float64))
    if total_energy == 0.0:
        raise InvalidArgumentError("clip is constant: every frame is the same, there is no dynamics to learn")
    step()

    method = svd if svd != "auto" else ("gram" if tau <= 1500 else "randomized")
    if method == "gram":
        basis, sv, states = _svd_gram(y, rank_cap if not auto else tau - 1)
    else:
        basis, sv, states = _svd_randomized(y, rank_cap, seed)
    del y
    step()
    return mean, basis, sv, states, total_energy, method


def _learn_subspace_streamed(
    clip: DiskClip, rank_cap: int, energy: float | None, max_memory: int | None, step, extra_rows: int = 0
):
    """Out of core: as :func:`_learn_subspace`, keeping ``rank_cap`` components (or, with
    ``energy``, the fewest that hold it, at least 2); ``extra_rows`` more pixel-sized rows
    (a caller's own basis) are counted in the memory plan."""
    width = plan_columns(clip, rank_cap + extra_rows, max_memory)
    mean, gram = gram_streamed(clip, width)
    total_energy = float(np.trace(gram))
    if total_energy == 0.0:
        raise InvalidArgumentError("clip is constant: every frame is the same, there is no dynamics to learn")
    step()
    sv, v = _eig_gram(gram)
    del gram
    rows = min(rank_cap, int(np.sum(sv > sv[0] * 1e-7)))
    if energy is not None:
        cum = np.cumsum(sv**2) / total_energy
        rows = min(rows, max(2, int(np.searchsorted(cum, energy) + 1)))
    basis = basis_streamed(clip, mean, v[:, :rows], sv[:rows], width)
    states = sv[:rows, None] * v[:, :rows].T
    basis, states = _fix_signs(basis, states)
    step()
    return mean, basis, sv[: clip.n_frames - 1], states, total_energy, -(-clip.pixels // width)


def _fit_dynamics(mean, basis, sv, x, total_energy, tau, k, max_radius, calibrate, energy, auto, method, step):
    """A, B, the stationary covariance and the info of an LDS on states ``x``."""
    n = basis.shape[0]
    x0, x1 = x[:, :-1], x[:, 1:]
    a_raw = np.linalg.lstsq(x0.T, x1.T, rcond=None)[0].T
    a, radius_raw, n_clipped = stabilize(a_raw, max_radius)
    resid = x1 - a @ x0
    u, s, _ = np.linalg.svd(resid, full_matrices=False)
    b = orient_rows(u[:, :k].T).T * (s[:k] / np.sqrt(tau - 1))
    cov = stationary_covariance(a, b @ b.T)
    train_cov = x @ x.T / tau
    q_gain = float(np.trace(train_cov) / np.trace(cov)) if calibrate else 1.0
    b *= np.sqrt(q_gain)
    cov *= q_gain
    step()

    info = {
        "svd": method,
        "n_auto": bool(auto),
        "energy": float(energy),
        "energy_captured": float(np.sum(sv[:n] ** 2) / total_energy),
        "spectral_radius_raw": float(radius_raw),
        "spectral_radius": float(np.max(np.abs(np.linalg.eigvals(a)))),
        "max_radius": float(max_radius),
        "poles_clipped": int(n_clipped),
        "q_gain": q_gain,
        "fit_residual": float(np.linalg.norm(resid) / np.linalg.norm(x1)),
        "tau": int(tau),
    }
    model = LDSModel(
        mean=mean,
        basis=basis,
        singular_values=sv.astype(np.float64),
        A=a,
        B=b,
        x0=x[:, 0].copy(),
        states=x,
        stationary_cov=cov,
        info=info,
    )
    step()
    return model


def stabilize(a: np.ndarray, max_radius: float) -> tuple[np.ndarray, float, int]:
    """Pull every pole of ``a`` with magnitude above ``max_radius`` back onto that circle.

    Returns the stabilized matrix, the original spectral radius and how many poles moved.
    """
    lam, v = np.linalg.eig(a)
    mags = np.abs(lam)
    radius = float(mags.max())
    over = mags > max_radius
    if not over.any():
        return a.copy(), radius, 0
    lam = np.where(over, lam / mags * max_radius, lam)
    a_s = (v * lam) @ np.linalg.inv(v)
    return np.ascontiguousarray(a_s.real), radius, int(over.sum())


def stationary_covariance(a: np.ndarray, q: np.ndarray, *, tol: float = 1e-12) -> np.ndarray:
    """Solve ``P = A P A.T + Q`` for a stable ``A`` by the doubling iteration."""
    p = q.copy()
    ak = a.copy()
    for _ in range(64):
        inc = ak @ p @ ak.T
        p = p + inc
        ak = ak @ ak
        if np.abs(inc).max() <= tol * max(np.abs(p).max(), 1e-300):
            break
    return (p + p.T) / 2


def plan_columns(clip: DiskClip, rows: int, max_memory: int | None) -> int:
    """Pixel columns per block of an out-of-core learn of ``rows`` basis rows within ``max_memory`` bytes.

    Counted: :data:`BASE_MEMORY`, the basis twice (the model and the database check's
    read-back), the mean, the Gram matrix and its eigendecomposition, and per column of a
    block its uint8 and float32 values and its projected rows.
    """
    bound = DEFAULT_MAX_MEMORY if max_memory is None else int(max_memory)
    tau, pixels = clip.n_frames, clip.pixels
    fixed = BASE_MEMORY + 2 * rows * pixels * 4 + 3 * pixels * 4 + 4 * tau * tau * 8
    per_column = tau * (1 + 4) + rows * 4 + 4
    width = (bound - fixed) // per_column
    if width < min(pixels, 1024):
        need = fixed + per_column * min(pixels, 1024)
        raise InvalidArgumentError(
            f"max_memory {bound / 2**30:.2f} GiB is too small for {clip.filename} "
            f"({tau} frames of {pixels} values, {rows} components): it needs at least "
            f"{need / 2**30:.2f} GiB"
        )
    return int(min(width, pixels))


def gram_streamed(clip: DiskClip, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean frame (float32) and the ``T x T`` Gram matrix (float64) of the mean-subtracted clip,
    summed over blocks of ``width`` pixel columns."""
    mean = np.empty(clip.pixels, np.float32)
    gram = np.zeros((clip.n_frames, clip.n_frames), np.float64)
    for p0, p1, b in _column_blocks(clip, width):
        mean[p0:p1] = b.mean(axis=0, dtype=np.float64)
        b -= mean[p0:p1]
        gram += b @ b.T
    return mean, gram


def _column_blocks(clip: DiskClip, width: int):
    """``(p0, p1, block)``: the clip's pixel columns ``p0:p1`` as float32 ``(T, p1 - p0)``, block
    after block (one buffer reused: a block is valid until the next is yielded)."""
    raw = np.empty((clip.n_frames, width), np.uint8)
    block = np.empty((clip.n_frames, width), np.float32)
    for p0 in range(0, clip.pixels, width):
        p1 = min(p0 + width, clip.pixels)
        b = block[:, : p1 - p0]
        np.copyto(b, clip.columns(p0, p1, raw))
        yield p0, p1, b


def basis_streamed(clip: DiskClip, mean: np.ndarray, v: np.ndarray, sv: np.ndarray, width: int) -> np.ndarray:
    """``(v / sv).T @ (Y - mean)``, the orthonormal basis rows, computed block by block."""
    coef = np.ascontiguousarray((v / sv[None, :]).T.astype(np.float32))
    basis = np.empty((coef.shape[0], clip.pixels), np.float32)
    for p0, p1, b in _column_blocks(clip, width):
        b -= mean[p0:p1]
        np.matmul(coef, b, out=basis[:, p0:p1])
    return basis


def _eig_gram(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (descending) and right singular vectors from a Gram matrix."""
    ev, v = np.linalg.eigh(gram)
    order = np.argsort(ev)[::-1]
    return np.sqrt(np.clip(ev[order], 0, None)), v[:, order]


def _svd_gram(y: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sv, v = _eig_gram((y @ y.T).astype(np.float64))
    n = min(n, int(np.sum(sv > sv[0] * 1e-7)))
    basis = (v[:, :n].T.astype(np.float32) @ y) / sv[:n, None].astype(np.float32)
    states = sv[:n, None] * v[:, :n].T
    basis, states = _fix_signs(basis, states)
    return basis, sv[: y.shape[0] - 1], states


def _svd_randomized(y: np.ndarray, n: int, seed: int, oversample: int = 10, power: int = 2):
    tau = y.shape[0]
    rng = np.random.default_rng(seed)
    width = min(n + oversample, tau)
    # Range of y.T (pixels x width), refined by power iterations.
    q, _ = np.linalg.qr(y.T @ rng.standard_normal((tau, width)).astype(np.float32))
    for _ in range(power):
        q, _ = np.linalg.qr(y.T @ (y @ q))
    small = (y @ q).T.astype(np.float64)  # width x tau
    ub, s, vt = np.linalg.svd(small, full_matrices=False)
    basis = (q @ ub[:, :n].astype(np.float32)).T
    states = s[:n, None] * vt[:n]
    basis, states = _fix_signs(np.ascontiguousarray(basis), states)
    return basis, s, states


def _fix_signs(basis: np.ndarray, states: np.ndarray):
    """Turn each component to its canonical sign (:mod:`.signs`), so the stored model does not
    depend on the solver or machine, and scale each row to unit length: a weak component's row
    ``v.T @ Y / s``, summed in float32, comes out a few parts in a thousand too long or short
    (the format checks 1e-3)."""
    sign = canonical_signs(basis)
    norms = np.sqrt(np.einsum("ij,ij->i", basis, basis, dtype=np.float64))
    scale = sign / np.where(norms > 0, norms, 1.0)
    return basis * scale[:, None].astype(basis.dtype), states * sign[:, None]


def _stepper(progress: Progress | None, total: int) -> Callable[[], None]:
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress:
            progress(done, total)

    return step
