"""The subspace-mixture dynamic texture of a texture (the ``mixture`` group).

Appearance: a mixture of ``S`` probabilistic PCA components of dimension ``d`` (learned in a
reduced PCA space), coordinated into one ``D``-dimensional global coordinate system by a
linear map ``L``. Dynamics: an AR(p) process on the global coordinates. A frame is
``mean + sum_j u_j stacked_basis[j]`` with ``u = (r_s, r_s z_s)`` per component, so the
player decodes a global coordinate to ``u`` and projects it like an LDS state.

The optional ``switching`` subgroup (format 1.6) holds dynamics the player prefers when present: a
Markov chain over the components and, per component, an AR process (its order the length of
``local_ar``'s second axis) on its local coordinates whose stationary covariance is the component's
own (``local_cov``), so the synthesis stays on each component's subspace and visits the components
as the clip does. Databases written without it play the AR process on the global coordinates.

The optional ``residual`` subgroup (played with ``switching`` only) holds what the components
leave out of each frame inside the reduced PCA space as a process of its own: ``k`` extra basis
rows and ``m`` axes, each axis a scalar AR process whose coordinate adds ``gain[a]`` to the
coefficients over the stacked rows and the extra ones. Databases written without it drop that
residual.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from . import detail as _detail
from . import gamut as _gamut
from . import tone as _tone
from ._check import Checker
from ._describe import Described
from ._parts import open_part, write_part
from .source import SourceInfo

#: Largest spectral radius the stored AR process's companion matrix may have.
MAX_SPECTRAL_RADIUS = 1.0 - 1e-9
#: Bounds on the model sizes a reader accepts (guards hostile files).
MAX_COMPONENTS = 64
MAX_DIM = 512
MAX_ORDER = 64
#: Version of the ``switching`` part this reader understands; a newer part is ignored (it is optional).
SWITCHING_VERSION = 1
SWITCHING_GROUP = "switching"
#: Version of the ``residual`` part this reader understands; a newer part is ignored (it is optional).
RESIDUAL_VERSION = 1
RESIDUAL_GROUP = "residual"
#: How far past the pixel range a component's ellipsoid of decoded coordinates may reach.
ELLIPSOID_SLACK = 4.0


@dataclass
class SwitchingDynamics:
    """Component-switching dynamics of a mixture (the optional ``switching`` subgroup).

    The component ``s_t`` follows a Markov chain; each component's local coordinates evolve,
    all the time, as ``z_t - c = sum_i A_i (z_{t-i} - c) + F e_t`` (``c`` the model's
    ``decode_offset``, ``e_t`` standard normal). A switch cross-fades the responsibilities from
    the old component to the new one.

    Attributes
    ----------
    transitions : (S, S) float64
        ``transitions[i, j]``: probability of component ``j`` after component ``i`` (rows sum to 1).
    local_ar : (S, p, d, d) float64
        ``A_1 .. A_p`` of each component (companion spectral radius < 1).
    local_noise : (S, d, d) float64
        ``F`` of each component (the driving noise's covariance is ``F F^T``).
    """

    transitions: np.ndarray
    local_ar: np.ndarray
    local_noise: np.ndarray


@dataclass
class ResidualProcess:
    """What a mixture's components leave out of each frame, played as a process of its own (the
    optional ``residual`` subgroup).

    Axis ``a``'s coordinate ``y_a`` follows ``y_a,t = sum_i ar[a, i] y_a,t-1-i + noise[a] e_t``
    (``e_t`` standard normal), and the frame's coefficients over the stacked rows followed by
    ``rows`` gain ``sum_a y_a gain[a]``.

    Attributes
    ----------
    rows : (k, P) float32
        Extra basis rows (orthonormal directions of the reduced space in pixels: norm at most 1);
        ``k`` may be 0.
    gain : (m, S * (d + 1) + k) float64
        Each axis as coefficients over the stacked rows and ``rows``.
    ar : (m, p) float64
        Each axis's AR coefficients (companion spectral radius < 1).
    noise : (m,) float64
        Standard deviation of each axis's driving noise (>= 0).
    """

    rows: np.ndarray
    gain: np.ndarray
    ar: np.ndarray
    noise: np.ndarray


@dataclass
class MixtureModel(Described):
    """A subspace-mixture dynamic texture.

    Attributes
    ----------
    mean : (P,) float32
        Mean frame, 0..255 (in tone units with a ``tone`` map).
    stacked_basis : (S * (d + 1), P) float32
        Component ``s`` owns rows ``s*(d+1) .. s*(d+1)+d``: its mean offset from ``mean``,
        then its ``d`` orthonormal loadings, all in pixel space (tone units with a ``tone`` map).
    weights : (S,) float64
        Mixing proportions ``pi_s`` (sum 1).
    sigma2 : (S,) float64
        Isotropic noise variance of each PPCA component (reduced-space units).
    singular_values : (r,) float64
        Singular values of the mean-subtracted clip (the reduced PCA space keeps ``q`` of them).
    responsibilities : (T, S) float64
        Posterior component probabilities of the training frames.
    local_coords : (T, S, d) float64
        Training frames' coordinates in each component's subspace.
    coord_map : (S * (d + 1), D) float64
        The coordination map ``L``: ``g = u @ L``.
    global_coords : (T, D) float64
        Training global coordinates (centred, unit covariance).
    gauss_mean, gauss_cov : (S, D), (S, D, D) float64
        Per-component Gaussian of the global coordinates, used to decode responsibilities.
    decode_offset, decode_gain : (S, d), (S, d, D) float64
        Decoding of local coordinates, ``z_s = decode_offset[s] + decode_gain[s] @ (g - gauss_mean[s])``:
        the conditional mean of ``z_s`` given ``g`` under component ``s``'s joint Gaussian of the
        training pairs (equal to the inverse of ``g_s = L_s z_s + l_s^0`` when that map is exact).
        ``decode_offset`` is also the responsibility-weighted mean of the training ``z_s``.
    local_cov, local_radius : (S, d, d), (S,) float64
        Responsibility-weighted covariance of the training ``z_s`` and the largest Mahalanobis
        radius of the frames the component owns: decoded ``z_s`` are pulled back inside that
        ellipsoid, where the local linear model is valid.
    ar_coefs : (p, D, D) float64
        ``g_t = ar_intercept + sum_i ar_coefs[i] @ g_{t-1-i} + v_t``.
    ar_intercept : (D,) float64
    ar_noise_cov : (D, D) float64
        Covariance of ``v_t``.
    sbc : (pmax,) float64
        Schwarz's criterion of the orders 1..pmax (the order chosen minimises it).
    info : dict
        Scalars describing the fit, stored as attributes.
    detail : DetailModel, optional
        The fine detail and colour range added to the projected frames (the optional ``detail``
        subgroup, :mod:`.detail`); None in databases written without it.
    gamut : GamutModel, optional
        The source's colour set, which the projected frames are held to (the optional ``gamut``
        subgroup, :mod:`.gamut`); None in databases written without it and for grey sources.
    switching : SwitchingDynamics, optional
        Component-switching dynamics on the local coordinates (the optional ``switching``
        subgroup); None in databases written without it.
    tone : ToneModel, optional
        The per-channel map from levels to the tone values the model was learned on (the
        required ``tone`` subgroup, :mod:`.tone`); None for a model learned on pixel values.
    residual : ResidualProcess, optional
        What the components leave out of each frame, as a process of its own (the optional
        ``residual`` subgroup); None in databases written without it.
    """

    mean: np.ndarray
    stacked_basis: np.ndarray
    weights: np.ndarray
    sigma2: np.ndarray
    singular_values: np.ndarray
    responsibilities: np.ndarray
    local_coords: np.ndarray
    coord_map: np.ndarray
    global_coords: np.ndarray
    gauss_mean: np.ndarray
    gauss_cov: np.ndarray
    decode_offset: np.ndarray
    decode_gain: np.ndarray
    local_cov: np.ndarray
    local_radius: np.ndarray
    ar_coefs: np.ndarray
    ar_intercept: np.ndarray
    ar_noise_cov: np.ndarray
    sbc: np.ndarray
    info: dict = field(default_factory=dict)
    detail: _detail.DetailModel | None = None
    gamut: _gamut.GamutModel | None = None
    switching: SwitchingDynamics | None = None
    tone: _tone.ToneModel | None = None
    residual: ResidualProcess | None = None

    def describe(self) -> dict:
        """Facts as plain values: the ``info`` attributes, the detail part's, the colour set's, the tone
        map's and the residual process's."""
        return {
            **super().describe(),
            **_detail.describe(self.detail, self.info),
            **_gamut.describe(self.gamut),
            **_tone.describe(self.tone),
            **self._residual_facts(),
        }

    def _residual_facts(self) -> dict:
        if self.residual is None:
            return {}
        res = self.residual
        return {"residual": f"{res.ar.shape[0]} axes, AR({res.ar.shape[1]}) each, {len(res.rows)} extra rows"}

    @property
    def components(self) -> int:
        return int(self.weights.shape[0])

    @property
    def dim(self) -> int:
        return int(self.local_coords.shape[2])

    @property
    def global_dim(self) -> int:
        return int(self.coord_map.shape[1])

    @property
    def order(self) -> int:
        return int(self.ar_coefs.shape[0])

    def summary(self) -> str:
        """One line: sizes, AR order, reconstruction error against a single PCA."""
        info = self.info
        dynamics = (
            f"AR({self.order}) by Schwarz"
            if self.switching is None
            else f"switching, AR({self.switching.local_ar.shape[1]}) per component"
        )
        return (
            f"S={self.components} d={self.dim} D={self.global_dim}, {dynamics}, "
            f"reconstruction error {info.get('recon_error', 0):.3f} (single PCA of d: "
            f"{info.get('recon_error_pca_dim', 0):.3f})"
            + (
                ""
                if self.residual is None
                else f", what the components leave out played by {self.residual.ar.shape[0]} axes"
            )
            + _tone.summary(self.tone)
        )


_F64 = (
    "weights",
    "sigma2",
    "singular_values",
    "responsibilities",
    "local_coords",
    "coord_map",
    "global_coords",
    "gauss_mean",
    "gauss_cov",
    "decode_offset",
    "decode_gain",
    "local_cov",
    "local_radius",
    "ar_coefs",
    "ar_intercept",
    "ar_noise_cov",
    "sbc",
)
_SIZES = ("components", "dim", "global_dim", "order")
_SWITCHING = ("transitions", "local_ar", "local_noise")
_RESIDUAL = ("gain", "ar", "noise")


def companion_radius(ar_coefs: np.ndarray) -> float:
    """Spectral radius of the AR(p) process's companion matrix (< 1 means stable)."""
    p, dd, _ = ar_coefs.shape
    comp = np.zeros((p * dd, p * dd))
    comp[:dd] = np.concatenate(list(ar_coefs), axis=1)
    comp[dd:, :-dd] = np.eye((p - 1) * dd)
    return float(np.max(np.abs(np.linalg.eigvals(comp))))


def write(group: h5py.Group, model: MixtureModel) -> None:
    group.create_dataset("mean", data=np.asarray(model.mean, np.float32))
    group.create_dataset(
        "stacked_basis", data=np.asarray(model.stacked_basis, np.float32), chunks=(1, model.stacked_basis.shape[1])
    )
    for name in _F64:
        group.create_dataset(name, data=np.asarray(getattr(model, name), np.float64))
    for name in _SIZES:
        group.attrs[name] = getattr(model, name)
    for key, value in model.info.items():
        if key not in _SIZES:
            group.attrs[key] = value
    _detail.write(group, model.detail)
    _gamut.write(group, model.gamut)
    if model.switching is not None:
        arrays = {name: np.asarray(getattr(model.switching, name), np.float64) for name in _SWITCHING}
        write_part(group, SWITCHING_GROUP, SWITCHING_VERSION, arrays)
    if model.residual is not None:
        arrays = {name: np.asarray(getattr(model.residual, name), np.float64) for name in _RESIDUAL}
        arrays["rows"] = np.asarray(model.residual.rows, np.float32)
        write_part(group, RESIDUAL_GROUP, RESIDUAL_VERSION, arrays, rows=("rows",))
    _tone.write(group, model.tone)


def read(group: h5py.Group, check: Checker, source: SourceInfo) -> MixtureModel:
    p = source.pixels
    path = group.name
    s = check.attr(group, "components", int)
    d = check.attr(group, "dim", int)
    dg = check.attr(group, "global_dim", int)
    order = check.attr(group, "order", int)
    for name, v, hi in (
        ("components", s, MAX_COMPONENTS),
        ("dim", d, MAX_DIM),
        ("global_dim", dg, MAX_DIM),
        ("order", order, MAX_ORDER),
    ):
        if not 1 <= v <= hi:
            check.fail(f"{path}@{name}", f"{v} out of range 1..{hi}")
    j = s * (d + 1)
    if dg > j - 1:
        check.fail(f"{path}@global_dim", f"{dg} exceeds components * (dim + 1) - 1 = {j - 1}")
    ds = check.dataset
    f = "f"
    frames = range(2, source.n_frames + 1)  # training arrays: a row per frame; SVD and SBC: at most as many
    model = MixtureModel(
        mean=ds(group, "mean", kind=f, shape=(p,)),
        stacked_basis=ds(group, "stacked_basis", kind=f, shape=(j, p)),
        weights=ds(group, "weights", kind=f, shape=(s,)),
        sigma2=ds(group, "sigma2", kind=f, shape=(s,)),
        singular_values=ds(group, "singular_values", kind=f, shape=(range(source.n_frames + 1),)),
        responsibilities=ds(group, "responsibilities", kind=f, shape=(frames, s)),
        local_coords=ds(group, "local_coords", kind=f, shape=(frames, s, d)),
        coord_map=ds(group, "coord_map", kind=f, shape=(j, dg)),
        global_coords=ds(group, "global_coords", kind=f, shape=(frames, dg)),
        gauss_mean=ds(group, "gauss_mean", kind=f, shape=(s, dg)),
        gauss_cov=ds(group, "gauss_cov", kind=f, shape=(s, dg, dg)),
        decode_offset=ds(group, "decode_offset", kind=f, shape=(s, d)),
        decode_gain=ds(group, "decode_gain", kind=f, shape=(s, d, dg)),
        local_cov=ds(group, "local_cov", kind=f, shape=(s, d, d)),
        local_radius=ds(group, "local_radius", kind=f, shape=(s,)),
        ar_coefs=ds(group, "ar_coefs", kind=f, shape=(order, dg, dg)),
        ar_intercept=ds(group, "ar_intercept", kind=f, shape=(dg,)),
        ar_noise_cov=ds(group, "ar_noise_cov", kind=f, shape=(dg, dg)),
        sbc=ds(group, "sbc", kind=f, shape=(range(order, source.n_frames + 1),)),
        info=check.info(group, skip=_SIZES),
        detail=_detail.read(group, check, source),
        gamut=_gamut.read(group, check, source),
        tone=_tone.read(group, check, source),
    )
    model.switching = _read_switching(group, check, model)
    t = model.global_coords.shape[0]
    if t < 2 or model.responsibilities.shape[0] != t or model.local_coords.shape[0] != t:
        check.fail(path + "/global_coords", "training arrays disagree on the number of frames (or fewer than 2)")
    if model.weights.min() < 0 or abs(model.weights.sum() - 1) > 1e-6:
        check.fail(path + "/weights", "mixing proportions must be >= 0 and sum to 1")
    if model.sigma2.min() <= 0:
        check.fail(path + "/sigma2", "noise variances must be > 0")
    r = model.responsibilities
    if r.min() < -1e-9 or r.max() > 1 + 1e-9 or np.abs(r.sum(axis=1) - 1).max() > 1e-6:
        check.fail(path + "/responsibilities", "rows must be probabilities summing to 1")
    for k in range(s):
        if not _positive_definite(model.gauss_cov[k]):
            check.fail(path + "/gauss_cov", f"covariance of component {k} is not symmetric positive definite")
    for k in range(s):
        if not _positive_definite(model.local_cov[k]):
            check.fail(path + "/local_cov", f"covariance of component {k} is not symmetric positive definite")
    if model.local_radius.min() <= 0:
        check.fail(path + "/local_radius", "radii must be > 0")
    if not _positive_definite(model.ar_noise_cov):
        check.fail(path + "/ar_noise_cov", "is not symmetric positive definite")
    rho = companion_radius(model.ar_coefs)
    if not rho < MAX_SPECTRAL_RADIUS:
        check.fail(path + "/ar_coefs", f"the AR process is not stable (spectral radius {rho:.6g} >= 1)")
    _tone.check_mean(path + "/mean", model.mean, model.tone, check)
    with np.errstate(all="ignore"):  # huge values overflow to inf, which every test below refuses
        row_norms = np.sqrt(np.einsum("jp,jp->j", model.stacked_basis, model.stacked_basis, dtype=np.float64))
        _check_extent(path, model, check, _tone.value_span(model.tone) * np.sqrt(p), row_norms)
    model.residual = _read_residual(group, check, model, source, row_norms)
    return model


def _read_switching(group: h5py.Group, check: Checker, model: MixtureModel) -> SwitchingDynamics | None:
    """The validated ``switching`` part, or None when absent or of a newer version."""
    s, d = model.components, model.dim
    g = open_part(group, SWITCHING_GROUP, SWITCHING_VERSION, check)
    if g is None:
        return None
    ds = check.dataset
    dyn = SwitchingDynamics(
        transitions=ds(g, "transitions", kind="f", shape=(s, s)),
        local_ar=ds(g, "local_ar", kind="f", shape=(s, range(1, MAX_ORDER + 1), d, d)),
        local_noise=ds(g, "local_noise", kind="f", shape=(s, d, d)),
    )
    t = dyn.transitions
    if not (np.isfinite(t).all() and t.min() >= 0 and np.abs(t.sum(axis=1) - 1).max() <= 1e-6):
        check.fail(g.name + "/transitions", "rows must be probabilities summing to 1")
    for k in range(s):
        rho = companion_radius(dyn.local_ar[k])
        if not rho < MAX_SPECTRAL_RADIUS:
            check.fail(g.name + "/local_ar", f"component {k}'s process is not stable (spectral radius {rho:.6g} >= 1)")
    var = np.einsum("sij,sij->s", dyn.local_noise, dyn.local_noise)
    own = np.trace(model.local_cov, axis1=1, axis2=2)
    if not (np.isfinite(var).all() and (var <= own * (1 + 1e-6)).all()):
        check.fail(g.name + "/local_noise", "the driving noise's variance exceeds the component's own (local_cov)")
    return dyn


def _read_residual(
    group: h5py.Group, check: Checker, model: MixtureModel, source: SourceInfo, stacked: np.ndarray
) -> ResidualProcess | None:
    """The validated ``residual`` part, or None when absent or of a newer version (``stacked``: the
    norms of the model's stacked rows, already checked)."""
    g = open_part(group, RESIDUAL_GROUP, RESIDUAL_VERSION, check)
    if g is None:
        return None
    ds = check.dataset
    j = model.components * (model.dim + 1)
    rows = ds(g, "rows", kind="f", shape=(range(MAX_DIM + 1), source.pixels))
    k = rows.shape[0]
    proc = ResidualProcess(
        rows=rows,
        gain=ds(g, "gain", kind="f", shape=(range(1, MAX_DIM + 1), j + k)),
        ar=ds(g, "ar", kind="f", shape=(range(1, MAX_DIM + 1), range(1, MAX_ORDER + 1))),
        noise=ds(g, "noise", kind="f", shape=(range(1, MAX_DIM + 1),)),
    )
    m = proc.gain.shape[0]
    if proc.ar.shape[0] != m or proc.noise.shape[0] != m:
        check.fail(g.name + "/ar", f"gain, ar and noise must have one row per axis ({m})")
    norms = np.sqrt(np.einsum("kp,kp->k", rows, rows, dtype=np.float64))
    if k and not norms.max() <= 1 + 1e-3:
        check.fail(g.name + "/rows", f"a row has norm {norms.max():.3g}: rows are orthonormal in the reduced space")
    if not proc.noise.min() >= 0:
        check.fail(g.name + "/noise", "standard deviations must be >= 0")
    gains = np.empty(m)
    for a in range(m):
        rho = companion_radius(proc.ar[a][:, None, None])
        if not rho < MAX_SPECTRAL_RADIUS:
            check.fail(g.name + "/ar", f"axis {a}'s process is not stable (spectral radius {rho:.6g} >= 1)")
        gains[a] = scalar_ar_gain(proc.ar[a])
    # Each axis's stationary spread in pixels, by the triangle inequality over the rows' norms.
    with np.errstate(all="ignore"):
        reach = proc.noise * np.sqrt(gains) * (np.abs(proc.gain) @ np.concatenate([stacked, norms]))
        bound = ELLIPSOID_SLACK * _tone.value_span(model.tone) * np.sqrt(source.pixels)
        if not reach.max() <= bound:
            check.fail(
                g.name + "/noise",
                f"an axis reaches {reach.max():.3g} per standard deviation, past {ELLIPSOID_SLACK:g} x the pixel "
                f"range ({bound:.3g})",
            )
    return proc


def scalar_ar_autocov(phi: np.ndarray, lags: int) -> np.ndarray:
    """Autocovariances ``gamma_0 .. gamma_lags`` of the stable scalar AR process with coefficients
    ``phi`` driven by unit noise: the ``p + 1`` Yule-Walker equations, then their recursion (a
    system of side ``p + 1``, so an order a damaged file states costs nothing to check).

    Examples
    --------
    >>> scalar_ar_autocov(np.array([0.5]), 2).round(4).tolist()   # 1 / (1 - 0.25), then x 0.5 a lag
    [1.3333, 0.6667, 0.3333]
    """
    phi = np.asarray(phi, dtype=np.float64).ravel()
    p = phi.size
    m = np.eye(p + 1)
    for k in range(p + 1):
        for i in range(1, p + 1):
            m[k, abs(k - i)] -= phi[i - 1]
    rhs = np.zeros(p + 1)
    rhs[0] = 1.0
    gamma = list(np.linalg.solve(m, rhs))
    for k in range(p + 1, lags + 1):
        gamma.append(float(sum(phi[i - 1] * gamma[k - i] for i in range(1, p + 1))))
    return np.array(gamma[: lags + 1])


def scalar_ar_gain(phi: np.ndarray) -> float:
    """Stationary variance of the stable scalar AR process with coefficients ``phi`` driven by unit noise."""
    return float(scalar_ar_autocov(phi, 0)[0])


def _check_extent(path: str, model: MixtureModel, check: Checker, bound: float, row_norms: np.ndarray) -> None:
    """Reject values that take synthesis out of the pixel range or to inf: loadings longer than
    1 (or all zero), component offsets and local ellipsoids beyond the pixel
    range, global coordinates that are not the stated centred unit-covariance cloud, and AR
    means, noise and Gaussians far outside that cloud (``row_norms``: the stacked rows' norms).

    Loadings are orthonormal vectors of the reduced PCA space mapped into pixels by its
    orthonormal basis (rows past the clip's rank are zero), so they never lengthen; a frame's
    deviation from the mean, hence each
    component's offset and decoded local coordinate, is at most ``256 sqrt(P)`` (with a tone map,
    :func:`.tone.value_span` for 256); the decoded
    coordinates are pulled back into each component's ellipsoid, whose semi-axes may exceed its
    frames' extent but not that bound by more than ``ELLIPSOID_SLACK``. ``T`` centred points of
    unit covariance in ``D`` dimensions lie within ``sqrt(T D)`` of the origin; so do their
    weighted means, and least-squares innovations have at most their total variance.
    """
    s, d = model.components, model.dim
    norms = row_norms.reshape(s, d + 1)
    if not norms[:, 1:].max() <= 1 + 1e-3:
        check.fail(
            path + "/stacked_basis",
            f"a loading row has norm {norms[:, 1:].max():.3g}: loadings are "
            "orthonormal in the reduced space, so at most 1 in pixels",
        )
    if not norms[:, 1:].max() >= 0.5:
        check.fail(path + "/stacked_basis", "every loading is (nearly) zero: the mixture has no appearance to vary")
    if not norms[:, 0].max() <= bound:
        check.fail(
            path + "/stacked_basis",
            f"a component's mean offset has norm {norms[:, 0].max():.3g}, outside the pixel range (<= {bound:.3g})",
        )
    offsets = np.sqrt((model.decode_offset**2).sum(axis=1))
    if not offsets.max() <= bound:
        check.fail(path + "/decode_offset", f"norm {offsets.max():.3g} lies outside the pixel range (<= {bound:.3g})")
    axes = model.local_radius * np.sqrt(np.linalg.eigvalsh(model.local_cov).max(axis=1))
    if not axes.max() <= ELLIPSOID_SLACK * bound:
        check.fail(
            path + "/local_radius",
            f"the ellipsoid of decoded coordinates reaches {axes.max():.3g}, past "
            f"{ELLIPSOID_SLACK:g} x the pixel range ({bound:.3g})",
        )
    g = model.global_coords
    t, dg = g.shape
    if not (np.abs(g.mean(axis=0)).max() <= 1e-6 and np.abs(g.T @ g / t - np.eye(dg)).max() <= 1e-6):
        check.fail(path + "/global_coords", "are not centred with unit covariance")
    cloud = np.sqrt(t * dg)
    ar_mean = np.linalg.solve(np.eye(dg) - model.ar_coefs.sum(axis=0), model.ar_intercept)
    for name, size in (
        ("gauss_mean", np.sqrt((model.gauss_mean**2).sum(axis=1)).max()),
        ("ar_intercept", np.sqrt(ar_mean @ ar_mean)),
    ):
        if not size <= cloud:
            check.fail(
                f"{path}/{name}", f"a mean of norm {size:.3g} lies outside the training coordinates (<= {cloud:.3g})"
            )
    if not np.trace(model.ar_noise_cov) <= t * dg:
        check.fail(
            path + "/ar_noise_cov",
            f"trace {np.trace(model.ar_noise_cov):.3g} exceeds the training coordinates' total variance {t * dg}",
        )


def _positive_definite(m: np.ndarray) -> bool:
    if not np.allclose(m, m.T, rtol=1e-9, atol=1e-12 * max(1.0, float(np.abs(m).max()))):
        return False
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        return False
    return True
