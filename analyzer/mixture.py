"""Learning subspace-mixture dynamic textures (Liu, Lin & Ahuja).

1. A reduced PCA space of ``q`` dimensions (the SVD helpers of :mod:`.lds`), for tractability.
2. A mixture of ``S`` probabilistic PCA components of dimension ``d`` fitted by EM
   (Tipping & Bishop; the M-step uses the closed-form ML solution for each component's
   responsibility-weighted covariance). Local coordinates ``z_s`` are the orthonormal
   coordinates in each component's principal subspace (a per-axis rescaling of the
   posterior mean, so the coordination absorbs the difference).
3. Global coordination (Teh & Roweis): ``u_nj = r_ns z^i_ns`` (``z^0 = 1``), LLE weights over
   ``K`` neighbours, and the generalized eigenproblem ``A v = lambda B v`` with
   ``A = U^T (I-W)^T (I-W) U`` and ``B = U^T U / N``, restricted to the centring constraint
   ``1^T U L = 0``; unit covariance ``L^T B L = I`` is the eigenvectors' normalisation.
4. AR(p) on the global coordinates, ``p = 1..pmax`` fitted by least squares on a common
   sample (Neumaier & Schneider) and chosen by Schwarz's criterion; an unstable fit is
   pulled back by scaling ``A_i -> c^i A_i``, which scales every pole by ``c``.
5. Switching dynamics (:func:`fit_switching`), which the player prefers: the AR process on the
   global coordinates is one Gaussian; the components' training coordinates are thin, separate
   clouds in that space, so its draws fall off every component's subspace and it can neither
   stay on them nor visit them as the clip does. Instead a Markov chain over the components
   (reversible, its stationary distribution the clip's occupancy) and, per component, an AR(2)
   process on its local coordinates along their principal axes (Yule-Walker on the component's
   own consecutive frames, its noise such that the stationary covariance is the component's
   ``local_cov``).
6. A residual process (:func:`fit_residual`), by default where the detail part is refused (a
   coarse truncation residual): what the components leave out of each training frame inside the
   PCA space (the PPCA noise: structured motion, not white) is kept where it is cheap to play:
   its part inside the span of the loadings, which the player projects through anyway, and along
   up to ``RESIDUAL_ROW_SHARE`` of the stacked rows' count of extra directions (the completion of
   that span holding most of what is left). Within that span the residual's
   principal axes each run an AR(2) process fitted on the training frames' residual coordinates,
   with the residual's variance, so that energy moves with the clip's own pace instead of being
   dropped.
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from ..tiledb import MixtureModel, ResidualProcess, SwitchingDynamics, ToneModel
from ..tiledb.mixture import companion_radius, scalar_ar_gain
from .deblock import choose as choose_grid
from .deblock import learning_values
from .detail import attach_detail
from .gamut import learn_gamut
from .lds import _learn_subspace_streamed, _stepper, _svd_gram, _svd_randomized
from .methods import check_params
from .signs import canonical_signs, orient_rows
from .stream import DiskClip
from .tone import choose as choose_tone
from .tone import gain_for, levels_of, pixel_sample
from .video import Clip, Progress, clip_frames

DEFAULT_COMPONENTS = 3
DEFAULT_DIM = 10
DEFAULT_PCA_DIM = 50
DEFAULT_NEIGHBORS = 12
DEFAULT_PMAX = 5
DEFAULT_MAX_RADIUS = 0.995
#: Order of each component's AR process on its local coordinates (switching dynamics).
LOCAL_ORDER = 2
LLE_REG = 1e-3
#: Extra basis rows the residual process may add, as a share of the stacked rows (the player's
#: cost a frame grows with its rows: at most 1.3 times today's).
RESIDUAL_ROW_SHARE = 0.3
#: A completion direction is kept only while it holds this share of the residual's energy or more.
RESIDUAL_MIN_SHARE = 1e-3
#: Least singular value of the loadings along a direction the residual process uses them for (each
#: axis then needs coefficients of at most 1 / RESIDUAL_REACH per unit).
RESIDUAL_REACH = 0.1


def learn_mixture(
    clip: Clip | DiskClip | np.ndarray,
    *,
    components: int = DEFAULT_COMPONENTS,
    dim: int = DEFAULT_DIM,
    global_dim: int | None = None,
    pca_dim: int = DEFAULT_PCA_DIM,
    neighbors: int = DEFAULT_NEIGHBORS,
    pmax: int | None = None,
    max_radius: float = DEFAULT_MAX_RADIUS,
    max_iter: int = 200,
    tol: float = 1e-6,
    tone: str = "auto",
    residual: str = "auto",
    deblock: str = "auto",
    seed: int = 0,
    max_memory: int | None = None,
    progress: Progress | None = None,
) -> MixtureModel:
    """Learn a subspace-mixture dynamic texture from a clip.

    Parameters
    ----------
    clip : Clip, DiskClip or ndarray
        Frames ``(T, H, W, C)`` uint8. A :class:`~dynatex.analyzer.stream.DiskClip` has its
        PCA stage learned out of core (as :func:`~dynatex.analyzer.lds.learn_lds` does).
    components : int
        Number ``S`` of PPCA components (>= 1; needs ``S * (dim + 1) < T``).
    dim : int
        Dimension ``d`` of each component (``1 <= d < pca_dim``).
    global_dim : int, optional
        Dimension ``D`` of the global coordinates (default ``dim``; at most ``S (d + 1) - 1``).
    pca_dim : int
        Dimension ``q`` of the reduced PCA space the mixture is fitted in (capped by the clip's rank).
    neighbors : int
        ``K`` nearest neighbours of the LLE reconstruction weights (``1 <= K < T``).
    pmax : int, optional
        Largest AR order tried; Schwarz's criterion picks ``p`` in ``1..pmax``. Default
        ``DEFAULT_PMAX`` (5), lowered to what the clip's length allows.
    max_radius : float
        Largest pole magnitude of the AR process, in (0, 1).
    max_iter, tol : int, float
        EM stops after ``max_iter`` iterations or when the log-likelihood gains less than
        ``tol`` (relative).
    tone : {"auto", "on", "off"}
        Learn on the clip's levels Gaussianised per channel, as :func:`~dynatex.analyzer.lds.learn_lds`
        does, and, with switching dynamics, calibrate the draws' variance in levels (info
        ``level_gain``).
    residual : {"auto", "on", "off"}
        Model what the components leave out of each frame inside the reduced PCA space as a process
        of its own (:func:`fit_residual`; the player adds it to each frame): ``auto`` where the
        model has no detail part (the truncation residual is coarse structure, which the detail's
        noise texture refuses, or the clip is streamed), ``on`` always (the detail then learned on
        what is left), ``off`` never (dropped, as before).
    deblock : {"auto", "on", "off"}
        Smooth away the block grid of a compressed clip before learning, as
        :func:`~dynatex.analyzer.lds.learn_lds` does.
    seed : int
        Seed of the EM initialisation (k-means++) and the randomized SVD.
    max_memory : int, optional
        Bytes an out-of-core PCA stage may use (default 2 GiB).
    progress : callable(done, total), optional
        Called after each of the 6 stages.

    Returns
    -------
    MixtureModel

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(60)[:, None, None, None]
    >>> x = np.arange(16)[None, None, :, None]
    >>> frames = (128 + 60 * np.sin(0.3 * t + 0.5 * x) + 0 * np.arange(8)[None, :, None, None]).astype(np.uint8)
    >>> m = learn_mixture(np.repeat(frames, 3, axis=3), components=2, dim=2, pca_dim=6, neighbors=6, pmax=3)
    >>> m.stacked_basis.shape, m.global_coords.shape, 1 <= m.order <= 3
    ((6, 384), (60, 2), True)
    """
    streamed = isinstance(clip, DiskClip)
    frames = None if streamed else clip_frames(clip)
    tau = clip.n_frames if streamed else frames.shape[0]
    components, dim, global_dim, pca_dim, neighbors, pmax, max_radius, max_iter, tol, tone, residual, deblock, seed = (
        check_params(
            "mixture",
            components=components,
            dim=dim,
            global_dim=global_dim,
            pca_dim=pca_dim,
            neighbors=neighbors,
            pmax=pmax,
            max_radius=max_radius,
            max_iter=max_iter,
            tol=tol,
            tone=tone,
            residual=residual,
            deblock=deblock,
            seed=seed,
        )
    )
    global_dim = dim if global_dim is None else global_dim
    if tau < 4:
        raise InvalidArgumentError(f"clip has {tau} frames; a subspace mixture needs at least 4")
    if components * (dim + 1) >= tau:
        raise InvalidArgumentError(
            f"components={components} with dim={dim} needs more than components * (dim + 1) = "
            f"{components * (dim + 1)} frames, the clip has {tau}; use fewer components or a smaller dim"
        )
    if dim >= pca_dim:
        raise InvalidArgumentError(f"dim={dim} must be smaller than pca_dim={pca_dim}")
    if global_dim > components * (dim + 1) - 1:
        raise InvalidArgumentError(
            f"global_dim={global_dim} exceeds components * (dim + 1) - 1 = {components * (dim + 1) - 1}"
        )
    if neighbors >= tau:
        raise InvalidArgumentError(f"neighbors={neighbors} must be smaller than the number of frames ({tau})")
    if pmax is None:
        # Largest p with T - p > (p + 1) D + 1, capped at the default.
        pmax = max(1, min(DEFAULT_PMAX, (tau - global_dim - 2) // (global_dim + 1)))
    if not tau - pmax > global_dim * pmax + 1 + global_dim:
        raise InvalidArgumentError(
            f"pmax={pmax} is too large for {tau} frames of {global_dim}-dimensional global "
            f"coordinates (needs T - pmax > (pmax + 1) * global_dim + 1); use a smaller pmax"
        )
    tone_map = choose_tone(frames, tone)
    grid, grid_info = choose_grid(frames, deblock)
    step = _stepper(progress, 6)

    # 1. Reduced PCA space.
    cap = min(pca_dim, tau - 1)
    if streamed:
        mean, basis, sv, states, total, _ = _learn_subspace_streamed(
            clip, cap, None, max_memory, lambda: None, extra_rows=components * (dim + 1)
        )
        constant = total <= 1e-6 * clip.pixels
    else:
        y, learned = learning_values(frames, grid, tone_map)
        mean = y.mean(axis=0, dtype=np.float64).astype(np.float32)
        y -= mean
        total = float(np.einsum("ij,ij->", y, y, dtype=np.float64))
        constant = total <= 1e-6 * y.shape[1]
        if not constant and tau <= 1500:
            basis, sv, states = _svd_gram(y, cap)
        elif not constant:
            basis, sv, states = _svd_randomized(y, cap, seed)
        del y
    if constant:
        raise InvalidArgumentError(
            "clip is constant: every frame is the same, there is no appearance variation to model"
        )
    q = int(min(cap, np.sum(sv > sv[0] * 1e-6)))
    if dim >= q:
        raise InvalidArgumentError(
            f"dim={dim} must be smaller than the clip's rank in the reduced space ({q}); use a smaller dim"
        )
    basis = np.ascontiguousarray(basis[:q])
    x = np.ascontiguousarray(states[:q].T)  # (T, q)
    step()

    # 2. Mixture of PPCA.
    ppca = fit_mppca(x, components, dim, max_iter=max_iter, tol=tol, seed=seed)
    r, z = ppca["resp"], ppca["z"]
    step()

    # 3. Global coordination.
    u = coefficient_matrix(r, z)
    w_idx, w = lle_weights(x, neighbors)
    lmap, eigvals = coordinate(u, w_idx, w, global_dim)
    g = u @ lmap
    gm, gc = _global_gaussians(g, r)
    dec_off, dec_gain = _decoders(g, r, z, gm, gc)
    loc_cov, loc_rad = _local_extent(r, z, dec_off)
    step()

    # 4. AR(p) by Schwarz's criterion.
    ar = fit_ar(g, pmax, max_radius=max_radius)
    step()

    # Pixel-space stacked basis: per component its mean offset, then its loadings.
    rows = []
    for s in range(components):
        rows.append(ppca["mu"][s][None, :])
        rows.append(ppca["U"][s].T)
    rows_q = np.concatenate(rows, axis=0)
    stacked = rows_q.astype(np.float32) @ basis
    inside = float(np.sum(x**2))
    rec = reconstruct(ppca, r, z)
    err_soft = (total - inside + float(np.sum((x - rec) ** 2))) / total
    hard = np.zeros_like(r)
    hard[np.arange(tau), r.argmax(axis=1)] = 1
    err_hard = (total - inside + float(np.sum((x - reconstruct(ppca, hard, z)) ** 2))) / total
    info = {
        "pca_dim": q,
        "neighbors": int(neighbors),
        "pmax": int(pmax),
        "seed": int(seed),
        "max_radius": float(max_radius),
        "em_iterations": int(ppca["iterations"]),
        "log_likelihood": float(ppca["loglik"]),
        "total_energy": total,
        "energy_pca_space": inside / total,
        "recon_error": err_soft,
        "recon_error_hard": err_hard,
        "recon_error_pca_dim": float(1 - np.sum(sv[:dim] ** 2) / total),
        "coordination_cost": float(np.sum(eigvals)),
        "spectral_radius_raw": float(ar["radius_raw"]),
        "spectral_radius": float(ar["radius"]),
        "ar_shrink": float(ar["shrink"]),
        "tau": int(tau),
        **grid_info,
    }
    model = MixtureModel(
        mean=mean,
        stacked_basis=np.ascontiguousarray(stacked),
        weights=ppca["pi"],
        sigma2=ppca["sigma2"],
        singular_values=sv.astype(np.float64),
        responsibilities=r,
        local_coords=z,
        coord_map=lmap,
        global_coords=g,
        gauss_mean=gm,
        gauss_cov=gc,
        decode_offset=dec_off,
        decode_gain=dec_gain,
        local_cov=loc_cov,
        local_radius=loc_rad,
        ar_coefs=ar["A"],
        ar_intercept=ar["w"],
        ar_noise_cov=ar["C"],
        sbc=ar["sbc"],
        info=info,
        switching=fit_switching(r, z, dec_off, loc_cov, max_radius=max_radius),
    )
    step()

    # 6. The detail, and the residual process inside the PCA space: with "auto" where the model has
    # no detail part (its residual coarse, or the clip streamed); with "on" first, the detail then
    # learned on what both leave out.
    u32, rows32 = u.astype(np.float32), model.stacked_basis
    if not streamed and residual != "on":
        attach_detail(model, learned, levels_of(lambda t0, t1: u32[t0:t1] @ rows32 + mean, tone_map), seed=seed)
    if residual == "on" or (residual == "auto" and model.detail is None):
        res_model, res_coords, res_info = fit_residual(x - rec, rows_q, dim, max_radius=max_radius)
        if res_model is not None:
            res_model.rows = np.ascontiguousarray(res_model.rows.astype(np.float32) @ basis)
            model.residual = res_model
            res_info["energy_model"] = 1.0 - err_soft + res_info["residual_process_energy"] / total
            res_info["residual_process_energy"] /= total
            model.info.update(res_info)
            u32 = np.concatenate([u32, np.zeros((tau, len(res_model.rows)), np.float32)], axis=1)
            u32 += (res_coords @ res_model.gain).astype(np.float32)
            rows32 = np.concatenate([rows32, res_model.rows])
        if not streamed and residual == "on":
            attach_detail(model, learned, levels_of(lambda t0, t1: u32[t0:t1] @ rows32 + mean, tone_map), seed=seed)
    if not streamed:
        if tone_map is not None:
            _calibrate_levels(model, r, u32, rows32, tone_map)
        model.gamut = learn_gamut(frames)
        model.tone = tone_map
    step()
    return model


def _calibrate_levels(model: MixtureModel, resp: np.ndarray, u: np.ndarray, rows: np.ndarray, tone: ToneModel) -> None:
    """Scale the variation a switching model draws about its components' means (their local
    covariances and AR noise, the residual axes' noise) so that its draws, mapped back to levels
    through ``tone``, have the variance there of its training reconstructions ``u @ rows + mean``
    (:func:`.tone.gain_for`; each component a Gaussian weighted by its share of the frames); info
    ``level_gain``. A model without switching dynamics is left as it is."""
    dyn = model.switching
    if dyn is None:
        return
    cols = pixel_sample(tone, rows.shape[1])
    m = model.mean[cols].astype(np.float64)
    sub = rows[:, cols].astype(np.float64)
    d = model.local_cov.shape[1]
    res_var = np.zeros(len(cols))
    if model.residual is not None:
        res = model.residual
        var = np.array([scalar_ar_gain(res.ar[a]) for a in range(len(res.ar))]) * res.noise**2
        along = res.gain @ sub[: res.gain.shape[1]]
        res_var = var @ along**2
    means, sds = [], []
    for s in range(len(model.local_cov)):
        top = s * (d + 1)
        load = sub[top + 1 : top + 1 + d]
        means.append(m + sub[top] + model.decode_offset[s] @ load)
        sds.append(np.sqrt(np.einsum("ip,ij,jp->p", load, model.local_cov[s], load) + res_var))
    gain = gain_for(tone, (u, sub, m), np.array(means), np.array(sds), resp.mean(axis=0))
    model.local_cov = model.local_cov * gain
    dyn.local_noise = dyn.local_noise * np.sqrt(gain)
    if model.residual is not None:
        model.residual.noise = model.residual.noise * np.sqrt(gain)
    model.info["level_gain"] = gain


# -- the residual process ------------------------------------------------------------------


def fit_residual(
    res: np.ndarray,
    rows: np.ndarray,
    dim: int,
    *,
    row_share: float = RESIDUAL_ROW_SHARE,
    order: int = LOCAL_ORDER,
    max_radius: float = DEFAULT_MAX_RADIUS,
) -> tuple[ResidualProcess | None, np.ndarray | None, dict]:
    """The residual process of the training frames' reduced-space residuals ``res`` (T, q) beside
    the stacked rows ``rows`` (S (dim + 1), q) (per component its mean offset, then its ``dim``
    orthonormal loadings, in reduced coordinates).

    The span the process lives in: the loadings' own (free: the player projects through them; only
    directions the loadings reach with singular value ``RESIDUAL_REACH`` or more, so that no axis
    needs large, cancelling coefficients) plus the ``k <= row_share * len(rows)`` orthonormal
    directions orthogonal to it that hold most of the residual (each at least
    ``RESIDUAL_MIN_SHARE`` of it). The residual projected on that span has ``m`` principal axes;
    each axis's coordinate runs an AR(``order``) process by Yule-Walker on its correlations over
    consecutive frames (the order lowered where they are not a valid sequence, poles within
    ``max_radius``), its noise such that the stationary variance is the axis's.

    Returns the process (its ``rows`` the ``k`` extra directions in reduced coordinates, for the
    caller to map into pixels; None when the span holds none of the residual), the training
    frames' axis coordinates ``(T, m)``, and facts for the model's info: ``residual_rows`` (``k``),
    ``residual_axes`` (``m``) and ``residual_process_energy`` (the energy kept, in the units of ``res``).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> res = rng.standard_normal((200, 6)) * [3, 2, 1, 0, 0, 0]
    >>> rows = np.array([[0, 0, 0, 0, 9, 0], [1, 0, 0, 0, 0, 0]])  # a mean offset, one loading
    >>> proc, coords, info = fit_residual(res, rows, 1, row_share=1.0)
    >>> info["residual_rows"], info["residual_axes"], coords.shape, proc.gain.shape
    (2, 3, (200, 3), (3, 4))
    """
    t, q = res.shape
    j = rows.shape[0]
    loading = np.ones(j, bool)
    loading[:: dim + 1] = False
    u, sv, _ = np.linalg.svd(rows[loading].T, full_matrices=False)
    own = u[:, sv >= RESIDUAL_REACH]  # (q, r): the span the loadings reach with bounded coefficients
    perp = res - (res @ own) @ own.T
    ev, vec = np.linalg.eigh(perp.T @ perp)
    ev, vec = ev[::-1], vec[:, ::-1]
    whole = float(np.sum(res * res))
    budget = min(int(row_share * j), q - own.shape[1])
    k = int(np.sum(ev[:budget] >= RESIDUAL_MIN_SHARE * whole)) if whole > 0 else 0
    extra = vec[:, :k]  # (q, k)
    span = np.concatenate([own, extra], axis=1)
    e = res @ span
    lam, axes = np.linalg.eigh(e.T @ e / t)
    lam, axes = lam[::-1], axes[:, ::-1]
    if not lam.size or lam[0] <= 0:
        return None, None, {"residual_rows": 0, "residual_axes": 0, "residual_process_energy": 0.0}
    keep = lam > lam[0] * 1e-9
    lam, axes = lam[keep], axes[:, keep]
    coords = e @ axes  # (T, m)
    m = coords.shape[1]
    order = max(1, min(order, t - 1))
    rho = _lag_correlations(coords, order, max_radius)
    ar = np.stack([_yule_walker(rho[:, a], max_radius) for a in range(m)])
    noise = np.sqrt(lam / np.array([scalar_ar_gain(phi) for phi in ar]))
    # Each axis as coefficients over the loadings (the mean offsets take none) and the extra rows.
    both = np.concatenate([rows[loading], extra.T], axis=0)
    coef = (span @ axes).T @ np.linalg.pinv(both, rcond=RESIDUAL_REACH / max(float(sv[0]), 1.0))
    gain = np.zeros((m, j + k))
    gain[:, np.concatenate([loading, np.ones(k, bool)])] = coef
    proc = ResidualProcess(rows=np.ascontiguousarray(extra.T), gain=gain, ar=ar, noise=noise)
    info = {"residual_rows": k, "residual_axes": m, "residual_process_energy": float(lam.sum() * t)}
    return proc, coords, info


# -- mixture of probabilistic PCA -----------------------------------------------------------


def fit_mppca(
    x: np.ndarray, components: int, dim: int, *, max_iter: int = 200, tol: float = 1e-6, seed: int = 0
) -> dict:
    """EM for a mixture of PPCA on rows of ``x`` (N, q).

    Returns a dict: ``pi`` (S,), ``mu`` (S, q), ``U`` (S, q, d) orthonormal loadings,
    ``lam`` (S, d) principal variances, ``sigma2`` (S,), ``resp`` (N, S), ``z`` (N, S, d),
    ``loglik`` (mean per point), ``iterations``. Raises ValueError when a component loses
    its data (too many components for the clip).
    """
    n, q = x.shape
    floor = 1e-6 * float(np.mean(np.var(x, axis=0))) + 1e-12
    resp = _kmeans_resp(x, components, seed)
    prev = -np.inf
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count of iterations is returned)
        params = _m_step(x, resp, dim, floor)
        logp = _log_gauss(x, params)
        top = logp.max(axis=1, keepdims=True)
        norm = top[:, 0] + np.log(np.exp(logp - top).sum(axis=1))
        resp = np.exp(logp - norm[:, None])
        loglik = float(norm.mean())
        if abs(loglik - prev) <= tol * abs(loglik):
            break
        prev = loglik
    params = _m_step(x, resp, dim, floor)
    z = np.einsum("nsq,sqd->nsd", x[:, None, :] - params["mu"][None], params["U"])
    return {**params, "resp": resp, "z": z, "loglik": loglik, "iterations": it}


def _m_step(x: np.ndarray, resp: np.ndarray, dim: int, floor: float) -> dict:
    n, q = x.shape
    nk = resp.sum(axis=0)
    s_count = resp.shape[1]
    if nk.min() < dim + 1:
        k = int(nk.argmin())
        raise InvalidArgumentError(
            f"component {k} holds only {nk[k]:.1f} frames' worth of data (needs more than "
            f"dim={dim}); the clip does not support {s_count} components: use fewer components "
            f"or a smaller dim"
        )
    mu = (resp.T @ x) / nk[:, None]
    us = np.empty((s_count, q, dim))
    lam = np.empty((s_count, dim))
    sigma2 = np.empty(s_count)
    for s in range(s_count):
        e = x - mu[s]
        cov = (e * resp[:, s : s + 1]).T @ e / nk[s]
        ev, vec = np.linalg.eigh(cov)
        ev, vec = ev[::-1], vec[:, ::-1]
        sigma2[s] = max(float(ev[dim:].mean()) if q > dim else floor, floor)
        lam[s] = np.maximum(ev[:dim], sigma2[s] * (1 + 1e-9))
        us[s] = orient_rows(vec[:, :dim].T).T
    return {"pi": nk / n, "mu": mu, "U": us, "lam": lam, "sigma2": sigma2}


def _log_gauss(x: np.ndarray, p: dict) -> np.ndarray:
    """``log pi_s + log N(x; mu_s, U diag(lam) U^T + sigma2 (I - U U^T))`` for every row and component."""
    n, q = x.shape
    out = np.empty((n, p["mu"].shape[0]))
    for s in range(p["mu"].shape[0]):
        e = x - p["mu"][s]
        c = e @ p["U"][s]
        sq = np.einsum("ij,ij->i", e, e)
        cs = np.einsum("ij,ij->i", c, c)
        maha = (c**2 / p["lam"][s]).sum(axis=1) + (sq - cs) / p["sigma2"][s]
        logdet = np.log(p["lam"][s]).sum() + (q - p["lam"].shape[1]) * np.log(p["sigma2"][s])
        out[:, s] = np.log(p["pi"][s]) - 0.5 * (q * np.log(2 * np.pi) + logdet + maha)
    return out


def _kmeans_resp(x: np.ndarray, k: int, seed: int, iters: int = 30) -> np.ndarray:
    """Hard responsibilities from k-means with k-means++ seeding."""
    rng = np.random.default_rng(seed)
    n = x.shape[0]
    centres = [x[rng.integers(n)]]
    for _ in range(1, k):
        d2 = np.min(((x[:, None, :] - np.array(centres)[None]) ** 2).sum(-1), axis=1)
        tot = d2.sum()
        centres.append(x[rng.choice(n, p=d2 / tot)] if tot > 0 else x[rng.integers(n)])
    c = np.array(centres)
    labels = np.zeros(n, int)
    for _ in range(iters):
        labels = ((x[:, None, :] - c[None]) ** 2).sum(-1).argmin(axis=1)
        for j in range(k):
            if np.any(labels == j):
                c[j] = x[labels == j].mean(axis=0)
    resp = np.zeros((n, k))
    resp[np.arange(n), labels] = 1.0
    # A little softness keeps every component alive for the first M-step.
    return 0.98 * resp + 0.02 / k


def reconstruct(ppca: dict, resp: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Reduced-space reconstruction ``sum_s r_s (mu_s + U_s z_s)``."""
    per = ppca["mu"][None] + np.einsum("sqd,nsd->nsq", ppca["U"], z)
    return np.einsum("ns,nsq->nq", resp, per)


# -- global coordination -----------------------------------------------------------------


def coefficient_matrix(resp: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``U`` with ``u_nj = r_ns z^i_ns``, ``j = s (d + 1) + i``, ``z^0 = 1``: (N, S (d + 1))."""
    n, s, d = z.shape
    ext = np.concatenate([np.ones((n, s, 1)), z], axis=2)
    return (resp[:, :, None] * ext).reshape(n, s * (d + 1))


def lle_weights(x: np.ndarray, k: int, reg: float = LLE_REG) -> tuple[np.ndarray, np.ndarray]:
    """LLE reconstruction weights: each row of ``x`` from its ``k`` nearest other rows, weights summing to 1.

    Returns neighbour indices (N, k) and weights (N, k).
    """
    sq = np.einsum("ij,ij->i", x, x)
    d2 = sq[:, None] + sq[None, :] - 2 * x @ x.T
    np.fill_diagonal(d2, np.inf)
    idx = np.argsort(d2, axis=1)[:, :k]
    diff = x[idx] - x[:, None, :]  # (N, k, q)
    gram = diff @ diff.transpose(0, 2, 1)  # (N, k, k)
    tr = np.trace(gram, axis1=1, axis2=2)
    gram += (reg * np.maximum(tr, 1e-12))[:, None, None] * np.eye(k)
    w = np.linalg.solve(gram, np.ones((x.shape[0], k, 1)))[..., 0]
    w /= w.sum(axis=1, keepdims=True)
    return idx, w


def coordinate(u: np.ndarray, idx: np.ndarray, w: np.ndarray, out_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The coordination map ``L`` (J, out_dim): the smallest generalized eigenvectors of
    ``A v = lambda B v`` subject to ``1^T U L = 0``; ``G = U L`` is centred with unit covariance.

    Returns ``L`` and its eigenvalues (the LLE cost of each global axis).
    """
    n, j = u.shape
    resid = u - np.einsum("nk,nkj->nj", w, u[idx])  # (I - W) U
    a = resid.T @ resid
    b = u.T @ u / n
    # Centring: 1^T U v = 0, i.e. v orthogonal to c = U^T 1. Work in c's orthogonal complement.
    c = u.sum(axis=0)
    qmat, _ = np.linalg.qr(np.concatenate([c[:, None], np.eye(j)], axis=1))
    null = qmat[:, 1:j]
    # Only directions U does not send to zero: on those (hard responsibilities can leave a few,
    # e.g. a component with barely more frames than dimensions) the cost is zero too, and they
    # would be chosen as global axes that are identically zero.
    bn = null.T @ b @ null
    ev_b, vec_b = np.linalg.eigh((bn + bn.T) / 2)
    keep = ev_b > 1e-9 * ev_b.max()
    if keep.sum() < out_dim:
        raise InvalidArgumentError(
            f"the mixture's coefficients span only {int(keep.sum())} dimensions, fewer than "
            f"global_dim={out_dim}; use a smaller global_dim or dim"
        )
    basis = null @ (vec_b[:, keep] / np.sqrt(ev_b[keep]))  # B-orthonormal
    an = basis.T @ a @ basis
    ev, vec = np.linalg.eigh((an + an.T) / 2)
    lmap = basis @ vec[:, :out_dim]
    # L^T B L = I to rounding; made exact.
    ev_b, vec_b = np.linalg.eigh(lmap.T @ b @ lmap)
    lmap = lmap @ (vec_b / np.sqrt(ev_b)) @ vec_b.T
    # Each global axis turned by the analyzer's one sign rule, on its coordinates over the clip.
    sign = canonical_signs((u @ lmap).T)
    return lmap * sign, ev[:out_dim]


def _global_gaussians(g: np.ndarray, resp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Responsibility-weighted Gaussian of the global coordinates per component (decodes responsibilities)."""
    nk = resp.sum(axis=0)
    dg = g.shape[1]
    means = (resp.T @ g) / nk[:, None]
    covs = np.empty((resp.shape[1], dg, dg))
    for s in range(resp.shape[1]):
        e = g - means[s]
        cov = (e * resp[:, s : s + 1]).T @ e / nk[s]
        covs[s] = (cov + cov.T) / 2 + 1e-4 * np.eye(dg)
    return means, covs


def _decoders(
    g: np.ndarray, resp: np.ndarray, z: np.ndarray, gm: np.ndarray, gc: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per component, the linear regression of ``z_s`` on ``g`` weighted by ``r_s``:
    ``E[z_s | g] = mean_z + Sigma_zg Sigma_gg^{-1} (g - mean_g)`` (bounded gain, unlike inverting ``L_s``)."""
    nk = resp.sum(axis=0)
    s_count, d = z.shape[1], z.shape[2]
    offs = np.empty((s_count, d))
    gains = np.empty((s_count, d, g.shape[1]))
    for s in range(s_count):
        offs[s] = resp[:, s] @ z[:, s] / nk[s]
        czg = ((z[:, s] - offs[s]) * resp[:, s : s + 1]).T @ (g - gm[s]) / nk[s]
        gains[s] = np.linalg.solve(gc[s], czg.T).T
    return offs, gains


def _local_extent(resp: np.ndarray, z: np.ndarray, means: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per component: weighted covariance of the training ``z_s`` and the largest Mahalanobis
    radius among the frames it owns (responsibility >= 0.5, or its most responsible frames)."""
    s_count, d = z.shape[1], z.shape[2]
    covs = np.empty((s_count, d, d))
    radii = np.empty(s_count)
    for s in range(s_count):
        e = z[:, s] - means[s]
        cov = (e * resp[:, s : s + 1]).T @ e / resp[:, s].sum()
        cov = (cov + cov.T) / 2
        cov += 1e-9 * max(np.trace(cov) / d, 1e-12) * np.eye(d)
        covs[s] = cov
        white = np.linalg.solve(np.linalg.cholesky(cov), e.T).T
        rad = np.sqrt((white**2).sum(axis=1))
        own = resp[:, s] >= min(0.5, resp[:, s].max())
        radii[s] = max(float(rad[own].max()), 1e-6)
    return covs, radii


# -- switching dynamics --------------------------------------------------------------------


def fit_switching(
    resp: np.ndarray,
    z: np.ndarray,
    offset: np.ndarray,
    local_cov: np.ndarray,
    *,
    order: int = LOCAL_ORDER,
    max_radius: float = DEFAULT_MAX_RADIUS,
) -> SwitchingDynamics:
    """Component-switching dynamics from the training responsibilities ``resp`` (N, S) and local
    coordinates ``z`` (N, S, d), around ``offset`` (S, d) with covariances ``local_cov`` (S, d, d).

    Transitions: the expected counts ``sum_t r_t r_{t+1}^T`` made symmetric (a reversible chain,
    whose stationary distribution is each component's share of the frames, even where the clip
    passes through its components once) plus ``1 / S`` of a count in every cell, so that no
    component is a trap. Per component and principal axis of ``local_cov`` (variance ``l``): an
    AR(``order``) process by Yule-Walker on the axis's correlations at lags ``1..order``, each
    over the windows of frames the component holds throughout (weights: the product of their
    responsibilities), the order lowered where those correlations are not a valid sequence; poles
    held within ``max_radius``; the noise scaled so that the stationary variance is ``l``. Order 2
    reproduces both how long the clip's motion persists and how smooth it is (AR(1) puts the
    excess of a random walk's power at the highest temporal frequencies: whole-frame flicker).

    Examples
    --------
    >>> r = np.repeat(np.eye(2), 50, axis=0)
    >>> z = np.random.default_rng(0).standard_normal((100, 2, 1))
    >>> dyn = fit_switching(r, z, np.zeros((2, 1)), np.ones((2, 1, 1)))
    >>> np.round(dyn.transitions, 3)
    array([[0.98, 0.02],
           [0.02, 0.98]])
    >>> dyn.local_ar.shape
    (2, 2, 1, 1)
    """
    n, s_count, d = z.shape
    counts = resp[:-1].T @ resp[1:]
    counts = (counts + counts.T) / 2 + 1.0 / s_count
    trans = counts / counts.sum(axis=1, keepdims=True)
    order = max(1, min(order, n - 1))
    ar = np.zeros((s_count, order, d, d))
    noise = np.empty((s_count, d, d))
    for s in range(s_count):
        lam, vec = np.linalg.eigh(local_cov[s])
        lam = np.maximum(lam, 0.0)
        # a lag-k pair's weight: the component's responsibilities over the window's k + 1 frames
        weights = [np.prod([resp[j : n - k + j, s] for j in range(k + 1)], axis=0) for k in range(1, order + 1)]
        rho = _lag_correlations((z[:, s] - offset[s]) @ vec, order, max_radius, weights)
        phi = np.zeros((order, d))
        gain = np.ones(d)
        for a in range(d):
            phi[:, a] = _yule_walker(rho[:, a], max_radius)
            gain[a] = scalar_ar_gain(phi[:, a])
        for i in range(order):
            ar[s, i] = (vec * phi[i]) @ vec.T
        noise[s] = vec * np.sqrt(lam / gain)
    return SwitchingDynamics(transitions=trans, local_ar=ar, local_noise=noise)


def _lag_correlations(
    y: np.ndarray, order: int, max_radius: float, weights: list[np.ndarray] | None = None
) -> np.ndarray:
    """The correlations ``(order + 1, d)`` of each column of ``y`` ``(N, d)`` with itself at lags
    ``0..order``: at lag ``k`` the pairs ``(y_t, y_{t+k})``, weighted by ``weights[k - 1]``
    ``(N - k,)`` (None: equally), against the mean energy of the two ends, clipped to ``max_radius``."""
    rho = np.ones((order + 1, y.shape[1]))
    for k in range(1, order + 1):
        w = 1.0 if weights is None else weights[k - 1][:, None]
        num = (w * y[k:] * y[:-k]).sum(axis=0)
        den = (w * (y[k:] ** 2 + y[:-k] ** 2)).sum(axis=0) / 2
        rho[k] = np.clip(num / np.maximum(den, 1e-300), -max_radius, max_radius)
    return rho


def _yule_walker(rho: np.ndarray, max_radius: float) -> np.ndarray:
    """AR coefficients (p,) from correlations ``rho`` (p + 1,) at lags 0..p, the order lowered
    until the correlations are positive definite, the poles scaled within ``max_radius``."""
    p = rho.size - 1
    phi = np.zeros(p)
    for q in range(p, 0, -1):
        toe = rho[np.abs(np.subtract.outer(np.arange(q + 1), np.arange(q + 1)))]
        if np.linalg.eigvalsh(toe).min() > 1e-6:
            phi[:q] = np.linalg.solve(toe[:q, :q], rho[1 : q + 1])
            break
    if not phi.any():
        return phi
    radius = float(np.abs(np.roots(np.concatenate([[1.0], -phi]))).max())
    if radius > max_radius:
        phi = phi * (max_radius / radius) ** np.arange(1, p + 1)
    return phi


# -- AR(p) by Schwarz's criterion -----------------------------------------------------------


def fit_ar(g: np.ndarray, pmax: int, *, max_radius: float = DEFAULT_MAX_RADIUS) -> dict:
    """Fit AR(p) with intercept for ``p = 1..pmax`` and keep the one minimising Schwarz's criterion.

    All orders are compared on the same sample (times ``pmax .. N-1``), as in Neumaier &
    Schneider's ARfit: ``SBC(p) = log det(Sigma_p) / m + (m p + 1) log(ne) / ne`` with
    ``Sigma_p`` the residual covariance and ``ne = N - pmax``. The chosen order is then
    refitted on every available sample.

    Returns a dict with ``A`` (p, m, m), ``w`` (m,), ``C`` (m, m), ``sbc`` (pmax,), ``p``,
    ``radius_raw``, ``radius`` and ``shrink`` (the pole scale applied for stability, 1 when none).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> g = np.zeros((2000, 1))
    >>> for t in range(2, 2000):
    ...     g[t] = 1.2 * g[t - 1] - 0.5 * g[t - 2] + rng.standard_normal(1)
    >>> fit_ar(g, 6)["p"]
    2
    """
    n, m = g.shape
    ne = n - pmax
    if ne - (m * pmax + 1) <= 0:
        raise InvalidArgumentError(f"pmax={pmax} is too large for {n} samples of dimension {m}")
    sbc = np.empty(pmax)
    for p in range(1, pmax + 1):
        _, _, resid = _ar_lstsq(g, p, start=pmax)
        cov = resid.T @ resid / ne
        sign, logdet = np.linalg.slogdet(cov)
        if sign <= 0:
            raise InvalidArgumentError(
                "the global coordinates are degenerate (singular AR residual covariance); "
                "the clip has too little variation for this global_dim"
            )
        sbc[p - 1] = logdet / m + (m * p + 1) * np.log(ne) / ne
    p = int(np.argmin(sbc)) + 1
    a, w, resid = _ar_lstsq(g, p, start=p)
    dof = max(resid.shape[0] - (m * p + 1), 1)
    c = resid.T @ resid / dof
    c = (c + c.T) / 2
    radius_raw = companion_radius(a)
    shrink = 1.0
    if radius_raw > max_radius:
        shrink = max_radius / radius_raw
        a = a * (shrink ** np.arange(1, p + 1))[:, None, None]
    return {
        "A": a,
        "w": w,
        "C": c,
        "sbc": sbc,
        "p": p,
        "radius_raw": radius_raw,
        "radius": companion_radius(a),
        "shrink": shrink,
    }


def _ar_lstsq(g: np.ndarray, p: int, start: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n, m = g.shape
    rows = np.arange(start, n)
    design = np.concatenate([np.ones((rows.size, 1))] + [g[rows - i] for i in range(1, p + 1)], axis=1)
    coef = np.linalg.lstsq(design, g[rows], rcond=None)[0]
    resid = g[rows] - design @ coef
    w = coef[0]
    a = coef[1:].reshape(p, m, m).transpose(0, 2, 1)
    return np.ascontiguousarray(a), w, resid
